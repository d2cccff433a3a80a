"""Network builders: the S3RL actor (policy encoder + Gaussian head) and the critics."""
