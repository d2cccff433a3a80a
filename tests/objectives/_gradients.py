"""Which parameter groups a loss term moves: the gradient-isolation check shared by the loss
tests (SAC-Lag, DDPG-Lag, PPO-Lag)."""

from __future__ import annotations

import torch


def moved(value: torch.Tensor, groups: dict[str, list[torch.Tensor]]) -> dict[str, bool]:
    """For each named group of parameters, whether ``value`` has a non-zero gradient on it."""
    flat = [p for ps in groups.values() for p in ps]
    gs = torch.autograd.grad(value, flat, retain_graph=True, allow_unused=True)
    result, i = {}, 0
    for name, ps in groups.items():
        result[name] = any(g is not None and bool(g.abs().sum() > 0) for g in gs[i : i + len(ps)])
        i += len(ps)
    return result
