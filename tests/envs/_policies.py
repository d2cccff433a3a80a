"""A policy shared by the env tests that compare our TorchRL env with a reference one."""

from __future__ import annotations

import numpy as np
import torch


class ReplayActions:
    """A policy that plays a fixed action sequence, so two envs can be stepped identically."""

    def __init__(self, actions: torch.Tensor | np.ndarray):
        self.actions, self.t = torch.as_tensor(actions), 0

    def __call__(self, td):
        td["action"] = self.actions[self.t]
        self.t += 1
        return td
