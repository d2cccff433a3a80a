"""The ``lagrangian`` buffer shared by the Lagrangian losses (SAC-Lag, DDPG-Lag, PPO-Lag).

A float buffer of shape ``[num_costs]``, set in place with :meth:`set_lagrangian` or
``loss.lagrangian = value`` (so that compiled graphs and optimisers holding the buffer see the
new value).
"""

from __future__ import annotations

import math
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
        if not isinstance(value, Tensor):
            # Numbers are checked in Python: a per-step controller sets lambda after every
            # gradient step, and tensor checks would cost ~25 us of it.
            values = [float(value)] * self.num_costs if isinstance(value, int | float) else [
                float(v) for v in value
            ]
            if len(values) != self.num_costs:
                raise ValueError(
                    f"lagrangian must be a number or {self.num_costs} values (one per cost), "
                    f"got {len(values)} values."
                )
            if not all(math.isfinite(v) and v >= 0 for v in values):
                raise ValueError(f"lagrangian must be finite and >= 0, got {values}.")
            buffer.copy_(torch.tensor(values, dtype=buffer.dtype))
            return
        value = value.detach().to(device=buffer.device, dtype=buffer.dtype)
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
