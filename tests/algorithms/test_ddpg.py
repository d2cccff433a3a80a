"""The DDPG family's gradient step (algorithms/ddpg.py): FSRL's order (critics, then the actor
on the updated critics, then the targets), with DDPG-Lag and with torchrl's DDPGLoss, against a
copy that takes the same steps by hand; the family's config checks."""

from __future__ import annotations

import pytest
import torch
from torchrl.objectives import DDPGLoss, SoftUpdate

from s3rl_torchrl.algorithms import (
    DDPG,
    ConfigError,
    DDPGConfig,
    ddpg_lag_update,
    make_ddpg_lag_optimizers,
)
from tests.objectives.test_ddpg_lag import GAMMA, make_batch, make_loss, make_nets


def test_update_step_follows_fsrl_order_and_soft_update_covers_cost_critic():
    loss, *_ = make_loss(1, lagrangian_init=0.3)
    optimizers = make_ddpg_lag_optimizers(loss, actor_lr=1e-3, critic_lr=1e-3)
    updater = SoftUpdate(loss, tau=0.05)
    n_actor = sum(
        p.numel() for p in loss.actor_network_params.values(True, True) if p.requires_grad
    )
    assert sum(p.numel() for g in optimizers["actor"].param_groups for p in g["params"]) == n_actor
    target_before = loss.target_cost_value_network_params.clone()
    online_before = loss.cost_value_network_params.clone()
    batch = make_batch()
    # Expected actor loss: computed after a separate copy takes the same critic step.
    twin, *_ = make_loss(1, lagrangian_init=0.3)
    twin_opt = make_ddpg_lag_optimizers(twin, actor_lr=1e-3, critic_lr=1e-3)
    critic = twin.critic_loss(batch.clone())
    (critic["loss_value"] + critic["loss_cost_value"]).backward()
    twin_opt["critic"].step()
    expected_actor, _ = twin.loss_actor(batch.clone())

    stats = ddpg_lag_update(loss, batch, optimizers, updater)
    torch.testing.assert_close(stats["loss_actor"], expected_actor.detach())
    for key in ("weight", "bias"):
        for path, target in target_before.items(True, True):
            if path[-1] != key:
                continue
            online_after = loss.cost_value_network_params.get(path)
            expected = 0.95 * target + 0.05 * online_after
            torch.testing.assert_close(loss.target_cost_value_network_params.get(path), expected)
            assert not torch.equal(online_after, online_before.get(path))


def test_update_step_with_torchrl_ddpgloss_follows_fsrl_order():
    # Unconstrained DDPG (s3rl-train algo=ddpg): torchrl's DDPGLoss, same step without costs.
    def ddpg():
        actor, critic, _ = make_nets(1)
        loss = DDPGLoss(actor, critic, delay_actor=True, delay_value=True)
        loss.make_value_estimator(gamma=GAMMA)
        return loss

    loss, twin = ddpg(), ddpg()
    optimizers = make_ddpg_lag_optimizers(loss, actor_lr=1e-3, critic_lr=1e-3)
    batch = make_batch()
    # Independent reference: torchrl's own losses, critic step first, then the actor loss.
    twin_opt = make_ddpg_lag_optimizers(twin, actor_lr=1e-3, critic_lr=1e-3)
    expected_value, _ = twin.loss_value(batch.clone())
    expected_value.backward()
    twin_opt["critic"].step()
    expected_actor, _ = twin.loss_actor(batch.clone())

    stats = ddpg_lag_update(loss, batch, optimizers, SoftUpdate(loss, tau=0.05))
    assert set(stats.keys()) == {"loss_actor", "loss_value", "reward_q"}
    torch.testing.assert_close(stats["loss_value"], expected_value.detach())
    torch.testing.assert_close(stats["loss_actor"], expected_actor.detach())
    torch.testing.assert_close(stats["reward_q"], -expected_actor.detach())


def test_ddpg_config_checks_its_own_fields():
    assert DDPG.config is DDPGConfig and not DDPG.seeds_in_one_process
    config = DDPGConfig(name="ddpg_lag")
    config.check("algo")
    assert not hasattr(config, "update_order") and not hasattr(config, "alpha_lr")
    config.exploration_noise = -0.1
    with pytest.raises(ConfigError, match="'algo.exploration_noise'"):
        config.check("algo")
