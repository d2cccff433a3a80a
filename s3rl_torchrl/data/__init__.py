"""Replay-buffer components for safe RL (samplers stratified by the safety label, the storage)."""

from s3rl_torchrl.data.sampler import (
    CONTRASTIVE_ROLE_KEY,
    LabelBinTooSmallError,
    SafeUnsafeSampler,
    StratumTooSmallError,
)
from s3rl_torchrl.data.storage import GatherStorage

__all__ = [
    "CONTRASTIVE_ROLE_KEY",
    "GatherStorage",
    "LabelBinTooSmallError",
    "SafeUnsafeSampler",
    "StratumTooSmallError",
]
