"""TorchRL transforms for safe RL."""

from s3rl_torchrl.transforms.cost_label import CostLabel
from s3rl_torchrl.transforms.episode_sum import EpisodeSum

__all__ = ["CostLabel", "EpisodeSum"]
