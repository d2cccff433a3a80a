"""Replay-buffer components for safe RL (samplers stratified by the safety label)."""

from s3rl_torchrl.data.sampler import (
    CONTRASTIVE_ROLE_KEY,
    LabelBinTooSmallError,
    SafeUnsafeSampler,
    StratumTooSmallError,
)

__all__ = [
    "CONTRASTIVE_ROLE_KEY",
    "LabelBinTooSmallError",
    "SafeUnsafeSampler",
    "StratumTooSmallError",
]
