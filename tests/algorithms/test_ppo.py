"""The PPO family's gradient step (algorithms/ppo.py): FSRL's minibatch step (the summed
losses, one backward, the global gradient-norm clip, Adam) against the step written out, with
PPO-Lag and with torchrl's ClipPPOLoss; the family's config checks and FSRL's defaults."""

from __future__ import annotations

import pytest
import torch
from torchrl.objectives import ClipPPOLoss

from s3rl_torchrl.algorithms import (
    PPO,
    ConfigError,
    PPOConfig,
    compute_ppo_advantages,
    make_ppo_lag_optimizers,
    ppo_lag_update,
)
from tests.objectives.test_ppo_lag import EPS, GAMMA, LMBDA, make_loss, make_nets, make_rollout


@pytest.mark.parametrize("max_grad_norm", [None, 0.05])
@pytest.mark.parametrize("constrained", [True, False])
def test_update_is_fsrls_one_adam_step_with_a_global_norm_clip(constrained, max_grad_norm):
    """ppo_lag_update against FSRL's step by hand: the summed losses, one backward, the norm of
    ALL the gradients (actor and critics) clipped to max_grad_norm, one Adam over everything."""
    def build():
        if constrained:
            loss, *_ = make_loss(lagrangian_init=0.5)
        else:
            actor, critic, _ = make_nets()
            loss = ClipPPOLoss(
                actor,
                critic,
                clip_epsilon=EPS,
                entropy_bonus=False,
                critic_coeff=0.25,
                loss_critic_type="l2",
            )
            loss.make_value_estimator(gamma=GAMMA, lmbda=LMBDA)
        return loss

    batch = make_rollout()
    ours, ref = build(), build()
    compute_ppo_advantages(ours, batch)
    batch = batch.reshape(-1)

    optimizers = make_ppo_lag_optimizers(ours, actor_lr=1e-2, critic_lr=1e-2)
    out = ppo_lag_update(ours, batch.clone(), optimizers, max_grad_norm)

    params = [p for p in ref.parameters() if p.requires_grad]
    adam = torch.optim.Adam(params, lr=1e-2)
    losses = ref(batch.clone())
    total = sum(v for k, v in losses.items() if k.startswith("loss_"))
    total.backward()
    norm = torch.sqrt(sum(p.grad.pow(2).sum() for p in params))
    if max_grad_norm is not None:
        assert norm > max_grad_norm  # the clip acts
        for p in params:
            p.grad.mul_(max_grad_norm / (norm + 1e-6))
    adam.step()
    torch.testing.assert_close(out["loss_objective"], losses["loss_objective"].detach())
    expected, initial = dict(ref.named_parameters()), dict(build().named_parameters())
    changed = 0
    for name, p in ours.named_parameters():
        torch.testing.assert_close(p, expected[name])
        changed += int(not torch.equal(p, initial[name]))
    assert changed > 0  # the step moved the weights


def test_ppo_config_has_fsrls_defaults_and_no_off_policy_fields():
    # fsrl/config/ppol_cfg.py: lr 5e-4 for actor and critics, gae_lambda 0.95, eps_clip 0.2,
    # vf_coef 0.25, max_grad_norm 0.5, repeat_per_collect 4, the unclipped cost term.
    assert PPO.config is PPOConfig and not PPO.seeds_in_one_process
    config = PPOConfig(name="ppo_lag")
    assert (config.actor_lr, config.critic_lr, config.gae_lambda, config.clip_epsilon) == (
        5e-4, 5e-4, 0.95, 0.2,
    )
    assert (config.critic_coeff, config.max_grad_norm, config.ppo_epochs) == (0.25, 0.5, 4)
    assert config.cost_surrogate == "unclipped"
    for field in ("n_step", "tau", "alpha_lr", "exploration_noise", "update_order"):
        assert not hasattr(config, field), field
    config.check("algo")
    config.ppo_epochs = 0
    with pytest.raises(ConfigError, match="'algo.ppo_epochs'"):
        config.check("algo")
