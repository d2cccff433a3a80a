"""Thin wrappers of the Hydra recipes in :mod:`s3rl_torchrl.recipes` (not installed)."""
