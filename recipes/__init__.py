"""Hydra entry points (thin): ``s3rl-train`` and ``s3rl-eval``."""
