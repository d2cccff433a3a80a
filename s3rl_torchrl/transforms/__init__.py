"""TorchRL transforms for safe RL."""

from s3rl_torchrl.transforms.cost_label import CostLabel
from s3rl_torchrl.transforms.cost_overlay import CostOverlay, is_marked, mark_frame
from s3rl_torchrl.transforms.cost_to_go import COST_TO_GO_KEY, CostToGo, discounted_cost_to_go
from s3rl_torchrl.transforms.episode_sum import EpisodeSum
from s3rl_torchrl.transforms.nstep import NStepTransform, make_nstep_transform, nstep_transition

__all__ = [
    "COST_TO_GO_KEY",
    "CostLabel",
    "CostOverlay",
    "CostToGo",
    "EpisodeSum",
    "NStepTransform",
    "discounted_cost_to_go",
    "is_marked",
    "make_nstep_transform",
    "mark_frame",
    "nstep_transition",
]
