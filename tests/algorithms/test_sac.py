"""The SAC family's gradient steps and optimisers (algorithms/sac.py): FSRL's three Adam
groups, FSRL's order against a hand reference, the joint step against a hand-written one, the
step the trainer builds for each ``update_order``, and the family's config checks."""

from __future__ import annotations

import copy

import pytest
import torch
from tensordict import TensorDict
from torchrl.objectives import SoftUpdate

from s3rl_torchrl.algorithms import (
    SAC,
    ConfigError,
    SACConfig,
    SACLagStep,
    joint_update,
    make_sac_lag_optimizers,
    sac_lag_update,
)
from s3rl_torchrl.objectives import ForeachSoftUpdate
from tests.objectives.test_sac_lag import ALPHA, close, make_batch, make_loss, sample


def ids(optimizer) -> set[int]:
    return {id(p) for group in optimizer.param_groups for p in group["params"]}


def ids_of(*tds) -> set[int]:
    return {id(p) for td in tds for p in td.values(True, True)}


def test_optimizers_cover_the_parameter_groups():
    loss, *_ = make_loss(2)
    opt = make_sac_lag_optimizers(loss, actor_lr=1e-4, critic_lr=2e-3, alpha_lr=3e-4)
    assert list(opt) == ["actor", "critic", "alpha"]
    assert ids(opt["actor"]) == ids_of(loss.actor_network_params)
    assert ids(opt["critic"]) == ids_of(loss.qvalue_network_params, loss.cost_qvalue_network_params)
    assert ids(opt["alpha"]) == {id(loss.log_alpha)}
    assert [o.param_groups[0]["lr"] for o in opt.values()] == [1e-4, 2e-3, 3e-4]
    assert all(o.defaults["fused"] for o in opt.values())
    fixed, *_ = make_loss(1, fixed_alpha=True)
    assert list(make_sac_lag_optimizers(fixed)) == ["actor", "critic"]
    with pytest.raises(ValueError, match="critic_lr must be > 0"):
        make_sac_lag_optimizers(loss, critic_lr=0.0)


def test_fsrl_order_update_uses_the_updated_critics():
    loss, actor, critics, costs = make_loss(1)
    loss.lagrangian = 0.8
    actor_before = copy.deepcopy(actor)
    optimizers = make_sac_lag_optimizers(loss, critic_lr=0.05)
    updater = SoftUpdate(loss, tau=0.05)
    targets_before = loss.target_qvalue_network_params.clone()
    critics_before = loss.qvalue_network_params.clone()
    log_alpha_before = float(loss.log_alpha.detach())
    batch = make_batch()
    torch.manual_seed(13)
    out = sac_lag_update(loss, batch, optimizers, updater)

    # Hand reference of the actor loss: the actor's sample before its own step, the critics
    # after theirs (FSRL), rescaled by 1 + lambda.
    torch.manual_seed(13)
    sample(actor_before, batch["next", "observation"])
    a, logp = sample(actor_before, batch["observation"])
    td = TensorDict({"observation": batch["observation"], "action": a}, [32])

    def q(params, module):
        values = []
        for j in range(params.shape[0]):
            with params[j].to_module(module):
                values.append(module(td.clone())[module.out_keys[0]].squeeze(-1))
        return torch.stack(values).min(0)[0]

    q_r, q_c = (
        q(loss.qvalue_network_params, critics[0]),
        q(loss.cost_qvalue_network_params, costs[0]),
    )
    expected = ((ALPHA * logp - q_r).mean() + 0.8 * q_c.mean()) / 1.8
    close(out["loss_actor"], expected)
    assert not torch.allclose(q_r, q(critics_before, critics[0]))  # the critics did move first
    # Soft update after the critic step, alpha stepped, the TD error at the priority key.
    expected_targets = targets_before.apply(
        lambda t, s: 0.95 * t + 0.05 * s, loss.qvalue_network_params
    )
    for key, value in expected_targets.flatten_keys().items():
        close(loss.target_qvalue_network_params.flatten_keys()[key], value)
    assert float(loss.log_alpha.detach()) != log_alpha_before
    assert batch.get("td_error").shape == (32,)
    assert set(out.keys()) == set(loss.out_keys)


def test_joint_update_is_one_backward_of_the_summed_losses():
    loss, *_ = make_loss(2)
    loss.lagrangian = [0.4, 0.9]
    twin = copy.deepcopy(loss)
    batch = make_batch(num_costs=2)
    # By hand: one forward, one backward of every loss_* summed, each Adam, the soft update.
    reference, twin_updater = make_sac_lag_optimizers(twin), ForeachSoftUpdate(twin, tau=0.05)
    torch.manual_seed(5)
    out = twin(batch.clone())
    (out["loss_actor"] + out["loss_qvalue"] + out["loss_cost_qvalue"] + out["loss_alpha"]).backward()
    for optimizer in reference.values():
        optimizer.step()
    twin_updater.step()
    optimizers = make_sac_lag_optimizers(loss)
    updater = ForeachSoftUpdate(loss, tau=0.05)
    torch.manual_seed(5)
    losses = joint_update(loss(batch.clone()), optimizers.values(), updater.step)
    assert not any(value.requires_grad for value in losses.values())
    close(losses["loss_actor"], out["loss_actor"].detach())
    twin_leaves = TensorDict.from_module(twin).flatten_keys()
    for key, value in TensorDict.from_module(loss).flatten_keys().items():
        close(value, twin_leaves[key], rtol=0, atol=0)
    # A stacked group's [K] losses: the sum over agents is what is backpropagated.
    weights = torch.nn.Parameter(torch.ones(3))
    sgd = torch.optim.SGD([weights], lr=1.0)
    joint_update(TensorDict({"loss_x": weights * 2.0}, []), [sgd], lambda: None)
    assert weights.tolist() == [-1.0, -1.0, -1.0]


@pytest.mark.parametrize("update_order", ["joint", "fsrl"])
def test_the_step_takes_the_configured_order(update_order):
    loss, *_ = make_loss(1)
    loss.lagrangian = 0.5
    twin = copy.deepcopy(loss)
    batch = make_batch()
    optimizers = make_sac_lag_optimizers(loss)
    step = SACLagStep(loss, optimizers, ForeachSoftUpdate(loss, tau=0.05), update_order)
    twin_optimizers = make_sac_lag_optimizers(twin)
    twin_updater = ForeachSoftUpdate(twin, tau=0.05)
    torch.manual_seed(2)
    out = step(batch.clone())
    torch.manual_seed(2)
    if update_order == "fsrl":
        expected = sac_lag_update(twin, batch.clone(), twin_optimizers, twin_updater)
    else:
        expected = joint_update(twin(batch.clone()), twin_optimizers.values(), twin_updater.step)
    for key in expected.keys():
        close(out[key], expected[key], rtol=0, atol=0)


def test_sac_config_checks_its_own_fields():
    assert SAC.config is SACConfig and SAC.seeds_in_one_process
    config = SACConfig(name="sac_lag")
    config.check("algo")
    for field, value, match in (
        ("update_order", "random", "'algo.update_order': allowed values are joint, fsrl"),
        ("cost_critic_read", "median", "'algo.cost_critic_read'"),
        ("alpha_lr", 0.0, "'algo.alpha_lr'"),
        ("n_step", 0, "'algo.n_step'"),
        ("tau", 0.0, "'algo.tau'"),
    ):
        bad = copy.deepcopy(config)
        setattr(bad, field, value)
        with pytest.raises(ConfigError, match=match):
            bad.check("algo")
