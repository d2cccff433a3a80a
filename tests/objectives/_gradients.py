"""Which parameter groups a loss term moves: the gradient-isolation checks shared by the loss
tests (SAC-Lag, DDPG-Lag, PPO-Lag; the contrastive ones: SafetyInfoNCE, GradedInfoNCE)."""

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


def assert_only_the_encoder_moves(loss_module, batch, actor, critic, encoder) -> None:
    """A contrastive loss's backward reaches the policy encoder's parameters (the loss holds the
    encoder's own parameters, not copies) and nothing else of the actor or the critic."""
    loss_module(batch)["loss_infonce"].backward()
    encoder_ids = {id(p) for p in encoder.parameters()}
    for name, param in actor.named_parameters():
        if id(param) in encoder_ids:
            assert param.grad is not None and param.grad.abs().sum() > 0, name
        else:
            assert param.grad is None, name
    assert all(p.grad is None for p in critic.parameters())
    assert {id(p) for p in loss_module.encoder_parameters()} == encoder_ids
