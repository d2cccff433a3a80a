"""The ``lagrangian`` buffer shared by the Lagrangian losses (DDPG-Lag, PPO-Lag).

Same contract as :class:`~s3rl_torchrl.objectives.SACLagLoss`: a float buffer of shape
``[num_costs]``, set in place with :meth:`set_lagrangian` or ``loss.lagrangian = value`` (so
that compiled graphs and optimisers holding the buffer see the new value).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


class LagrangianBufferMixin:
    """Mix into a ``LossModule`` with a ``num_costs`` attribute; call :meth:`_init_lagrangian`."""

    num_costs: int

    def _init_lagrangian(self, value: float | Sequence[float] | Tensor, device=None) -> None:
        self.register_buffer("lagrangian", torch.zeros(self.num_costs, device=device))
        self.set_lagrangian(value)

    def set_lagrangian(self, value: float | Sequence[float] | Tensor) -> None:
        """Set the multipliers in place: a number (same for every cost) or ``num_costs`` values."""
        buffer = self._buffers["lagrangian"]
        if isinstance(value, Tensor):
            value = value.detach().to(device=buffer.device, dtype=buffer.dtype)
        else:
            value = torch.as_tensor(value, dtype=buffer.dtype, device=buffer.device)
        if value.ndim == 0:
            value = value.expand(self.num_costs)
        if value.shape != buffer.shape:
            raise ValueError(
                f"lagrangian must be a number or {self.num_costs} values (one per cost), got "
                f"shape {tuple(value.shape)}."
            )
        if not bool(torch.isfinite(value).all()) or bool((value < 0).any()):
            raise ValueError(f"lagrangian must be finite and >= 0, got {value.tolist()}.")
        buffer.copy_(value)

    def __setattr__(self, name, value):
        if name == "lagrangian" and "lagrangian" in self.__dict__.get("_buffers", {}):
            self.set_lagrangian(value)
            return
        super().__setattr__(name, value)
