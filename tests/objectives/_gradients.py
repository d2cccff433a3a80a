"""Which parameter groups a loss term moves: the gradient-isolation checks shared by the loss
tests (SAC-Lag, DDPG-Lag, PPO-Lag; the contrastive ones: SafetyInfoNCE, GradedInfoNCE), and the
momentum-encoder check the two contrastive losses share."""

from __future__ import annotations

import pytest
import torch
from torchrl.objectives import SoftUpdate


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


def assert_momentum_encoder(loss_module, encoder, batch, reference) -> None:
    """A contrastive loss with ``momentum_encoder=True`` on a batch of 3 anchors, 3 positives and
    3 negatives: its value and its gradient are ``reference(anchors, positives, negatives)`` with
    the anchors embedded by the online encoder and the rest by a detached copy (at the start the
    target equals the online encoder), and ``SoftUpdate(tau=0.1)`` moves the target a tenth of the
    way to the online parameters."""
    updater = SoftUpdate(loss_module, tau=0.1)
    out = loss_module(batch)
    with torch.no_grad():
        z = encoder(batch.select("observation").clone())["embedding"]
    z_anchor = encoder.module(batch["observation"][:3])
    expected_loss = reference(z_anchor, z[3:6], z[6:9])
    assert out["loss_infonce"].item() == pytest.approx(expected_loss.item(), rel=1e-5)
    grads = torch.autograd.grad(out["loss_infonce"], list(encoder.parameters()))
    expected = torch.autograd.grad(expected_loss, list(encoder.parameters()))
    for got, want in zip(grads, expected):
        torch.testing.assert_close(got, want)

    target_before = loss_module.target_encoder_params.clone()
    with torch.no_grad():
        for p in encoder.parameters():
            p.add_(1.0)
    updater.step()
    for key, online in loss_module.encoder_params.items(True, True):
        target = loss_module.target_encoder_params.get(key)
        torch.testing.assert_close(target, 0.9 * target_before.get(key) + 0.1 * online.detach())
        assert not target.requires_grad
