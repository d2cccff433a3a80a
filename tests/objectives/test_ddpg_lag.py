"""DDPGLagLoss against torchrl's DDPGLoss and against hand computations of FSRL's DDPG-Lag."""

from __future__ import annotations

import copy
import math

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded, LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import DDPGLoss

from s3rl_torchrl.algorithms import ContrastivePhase
from s3rl_torchrl.data.sampler import SafeUnsafeSampler
from s3rl_torchrl.modules import (
    build_ddpg_exploration,
    build_deterministic_actor,
    build_qvalue_network,
    get_policy_encoder,
)
from s3rl_torchrl.objectives import DDPGLagLoss, SafetyInfoNCELoss
from tests.objectives._gradients import moved

OBS, ACT, HIDDEN, GAMMA = 5, 2, (16, 16), 0.9
COST_KEY = "state_action_cost_value"


def action_spec() -> Bounded:
    return Bounded(torch.tensor([-1.0, -2.0]), torch.tensor([1.0, 0.5]), (ACT,))


def make_nets(num_costs: int = 1, seed: int = 0):
    torch.manual_seed(seed)
    actor = build_deterministic_actor(OBS, action_spec(), HIDDEN)
    critic = build_qvalue_network(OBS, ACT, HIDDEN)
    cost_critic = build_qvalue_network(OBS, ACT, HIDDEN, num_costs, out_key=COST_KEY)
    return actor, critic, cost_critic


def make_loss(num_costs: int = 1, **kwargs):
    actor, critic, cost_critic = make_nets(num_costs)
    loss = DDPGLagLoss(actor, critic, cost_critic, num_costs=num_costs, **kwargs)
    loss.make_value_estimator(gamma=GAMMA)
    return loss, actor, critic, cost_critic


def make_batch(batch: int = 32, num_costs: int = 1, seed: int = 2, steps: bool = True):
    g = torch.Generator().manual_seed(seed)
    terminated = torch.rand(batch, 1, generator=g) < 0.3
    cost = torch.rand(batch, num_costs, generator=g) * torch.arange(1, num_costs + 1) ** 2
    data = {
        "observation": torch.randn(batch, OBS, generator=g),
        "action": torch.rand(batch, ACT, generator=g) * 2 - 1,
        "next": {
            "observation": torch.randn(batch, OBS, generator=g),
            "reward": torch.randn(batch, 1, generator=g),
            "cost": cost,
            "terminated": terminated,
            "done": terminated | (torch.rand(batch, 1, generator=g) < 0.2),
        },
    }
    if steps:
        data["steps_to_next_obs"] = torch.randint(1, 3, (batch, 1), generator=g)
    return TensorDict(data, [batch])


def perturb_(params, seed: int) -> None:
    """Give target parameters their own values, so that a target/online mix-up shows."""
    g = torch.Generator().manual_seed(seed)
    for p in params.values(True, True):
        p.data.add_(0.1 * torch.randn(p.shape, generator=g))


def flat_grads(params) -> list[torch.Tensor]:
    return [
        torch.zeros_like(p) if p.grad is None else p.grad.clone()
        for p in params.values(True, True)
    ]


@pytest.mark.parametrize("rescaling", [True, False])
def test_zero_lagrangian_matches_ddpgloss(rescaling):
    """At lambda = 0 the actor and reward-critic losses and gradients are DDPGLoss's."""
    lag, actor, critic, _ = make_loss(rescaling=rescaling)
    ref = DDPGLoss(copy.deepcopy(actor), copy.deepcopy(critic), delay_actor=True, loss_function="l2")
    ref.make_value_estimator(gamma=GAMMA)
    for loss in (lag, ref):  # same (non-trivial) target networks in both losses
        perturb_(loss.target_actor_network_params, 5)
        perturb_(loss.target_value_network_params, 6)
    batch = make_batch()
    out_lag, out_ref = lag(batch.clone()), ref(batch.clone())
    for key in ("loss_actor", "loss_value", "target_value", "pred_value"):
        torch.testing.assert_close(out_lag[key], out_ref[key], rtol=0, atol=0)
    for out in (out_lag, out_ref):
        (out["loss_actor"] + out["loss_value"]).backward()
    for name in ("actor_network_params", "value_network_params"):
        for g_lag, g_ref in zip(
            flat_grads(getattr(lag, name)), flat_grads(getattr(ref, name)), strict=True
        ):
            torch.testing.assert_close(g_lag, g_ref, rtol=0, atol=0)


@pytest.mark.parametrize("rescaling", [True, False])
def test_actor_loss_two_costs_by_hand(rescaling):
    loss, actor, critic, cost_critic = make_loss(2, rescaling=rescaling)
    lagrangian = torch.tensor([0.4, 1.3])
    loss.set_lagrangian(lagrangian)
    batch = make_batch(num_costs=2)
    with torch.no_grad():
        obs = batch["observation"]
        td = actor(TensorDict(observation=obs, batch_size=[len(obs)]))
        q_r = critic(td.clone())["state_action_value"].squeeze(-1)
        q_c = cost_critic(td.clone())[COST_KEY]
    expected = (-q_r + q_c @ lagrangian).mean()
    if rescaling:
        expected = expected / (1 + lagrangian.sum())
    out = loss(batch)
    torch.testing.assert_close(out["loss_actor"], expected)
    torch.testing.assert_close(out["reward_q"], q_r.mean())
    torch.testing.assert_close(out["cost_q"], q_c.mean(0))
    torch.testing.assert_close(out["lagrangian"], lagrangian)


def test_cost_critic_loss_by_hand_with_target_networks_and_nsteps():
    loss, actor, _, cost_critic = make_loss(2)
    perturb_(loss.target_actor_network_params, 7)
    perturb_(loss.target_cost_value_network_params, 8)
    batch = make_batch(num_costs=2)
    target_actor, target_cost = copy.deepcopy(actor), copy.deepcopy(cost_critic)
    loss.target_actor_network_params.to_module(target_actor)
    loss.target_cost_value_network_params.to_module(target_cost)
    with torch.no_grad():
        next_td = TensorDict(observation=batch["next", "observation"], batch_size=[32])
        next_q = target_cost(target_actor(next_td))[COST_KEY]
        gamma_k = GAMMA ** batch["steps_to_next_obs"].float()
        not_term = 1 - batch["next", "terminated"].float()
        y = batch["next", "cost"] + gamma_k * not_term * next_q
        pred = cost_critic(batch.select("observation", "action").clone())[COST_KEY]
    expected = ((pred - y) ** 2).sum(-1).mean()
    out = loss(batch)
    torch.testing.assert_close(out["loss_cost_value"], expected)
    torch.testing.assert_close(loss.cost_targets(batch), y)


def test_gradient_isolation():
    loss, *_ = make_loss(2)
    loss.set_lagrangian([0.5, 0.7])
    out = loss(make_batch(num_costs=2))
    groups = {
        name: [p for p in params.values(True, True) if p.requires_grad]
        for name, params in (
            ("actor", loss.actor_network_params),
            ("critic", loss.value_network_params),
            ("cost_critic", loss.cost_value_network_params),
        )
    }

    assert moved(out["loss_value"], groups) == {"actor": False, "critic": True, "cost_critic": False}
    assert moved(out["loss_cost_value"], groups) == {
        "actor": False,
        "critic": False,
        "cost_critic": True,
    }
    assert moved(out["loss_actor"], groups) == {"actor": True, "critic": False, "cost_critic": False}


def test_lagrangian_setter_validation_and_state_dict():
    loss, *_ = make_loss(2)
    loss.lagrangian = 0.5
    torch.testing.assert_close(loss.lagrangian, torch.tensor([0.5, 0.5]))
    with pytest.raises(ValueError, match="finite and >= 0"):
        loss.set_lagrangian([-1.0, 0.0])
    with pytest.raises(ValueError, match="2 values"):
        loss.set_lagrangian([1.0, 2.0, 3.0])
    fresh, *_ = make_loss(2)
    fresh.load_state_dict(loss.state_dict())
    torch.testing.assert_close(fresh.lagrangian, torch.tensor([0.5, 0.5]))


def test_wrong_cost_shape_and_bad_arguments():
    loss, *_ = make_loss(2)
    with pytest.raises(ValueError, match="num_costs=2"):
        loss(make_batch(num_costs=1))
    actor, critic, cost_critic = make_nets()
    with pytest.raises(ValueError, match="num_costs must be an integer >= 1"):
        DDPGLagLoss(actor, critic, cost_critic, num_costs=0)
    with pytest.raises(ValueError, match="lagrangian"):
        DDPGLagLoss(actor, critic, cost_critic, lagrangian_init=-1.0)


def test_in_keys_include_the_cost():
    loss, *_ = make_loss()
    assert ("next", "cost") in loss.in_keys
    assert ("next", "observation") in loss.in_keys


# ---------------------------------------------------------------- actor and exploration
def test_deterministic_actor_bounds_and_exploration_noise():
    actor = make_nets()[0]
    spec = action_spec()
    low, high = spec.space.low, spec.space.high
    obs = torch.randn(4000, OBS, generator=torch.Generator().manual_seed(0)) * 50
    td = TensorDict(observation=obs, batch_size=[4000])
    with torch.no_grad():
        action = actor(td.clone())["action"]
        # Large inputs saturate tanh: the actions reach (not exceed) the bounds.
        assert bool(((action >= low) & (action <= high)).all())
        explore = build_ddpg_exploration(actor, spec, sigma=0.1)
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            torch.testing.assert_close(explore(td.clone())["action"], action)
        calm = TensorDict(observation=torch.zeros(4000, OBS), batch_size=[4000])
        mean_action = actor(calm.clone())["action"]
        torch.manual_seed(1)
        noisy = explore(calm.clone())["action"]
    assert bool(((noisy >= low) & (noisy <= high)).all())
    # sigma = 0.1 in tianshou's [-1, 1] scale: std 0.1 * half range per dimension (the zero
    # observation gives the mid action with zero biases, far from the bounds).
    torch.testing.assert_close(mean_action, ((low + high) / 2).expand_as(mean_action))
    std = (noisy - mean_action).std(0)
    torch.testing.assert_close(std, 0.1 * (high - low) / 2, rtol=0.05, atol=0)
    assert any(p is q for p in explore.parameters() for q in actor.parameters())


def test_contrastive_phase_plugs_into_the_ddpg_actor_unchanged():
    """The algorithm-agnostic claim: the S3RL encoder phase on DDPG-Lag's actor."""
    loss, actor, critic, cost_critic = make_loss()
    encoder = get_policy_encoder(actor)
    n = 400
    g = torch.Generator().manual_seed(0)
    safe = torch.rand(n, generator=g) > 0.3
    obs = torch.randn(n, OBS, generator=g)
    obs[:, 0] += torch.where(safe, 1.0, -1.0)
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(n),
        sampler=SafeUnsafeSampler(),
        generator=torch.Generator().manual_seed(1),
    )
    rb.extend(TensorDict(observation=obs, next={"safe": safe[:, None]}, batch_size=[n]))
    infonce = SafetyInfoNCELoss(encoder)
    phase = ContrastivePhase(infonce, SafeUnsafeSampler.contrastive_view(rb, 32), 1e-2, 20)
    encoder_ids = {id(p) for p in encoder.parameters()}
    before = {name: p.detach().clone() for name, p in actor.named_parameters()}
    loss_before = loss(make_batch())["loss_actor"].item()
    fixed = phase.source.sample()
    info_before = infonce(fixed)["loss_infonce"].item()

    stats = phase.run()

    assert stats is not None and infonce(fixed)["loss_infonce"].item() < info_before
    for name, p in actor.named_parameters():
        moved = not torch.equal(before[name], p.detach())
        assert moved == (id(p) in encoder_ids), name
    # The DDPG-Lag loss holds the same parameters: its actor loss sees the new encoder.
    assert not math.isclose(loss(make_batch())["loss_actor"].item(), loss_before)
    for p in (*critic.parameters(), *cost_critic.parameters()):
        assert p.grad is None


def test_deterministic_actor_formula_and_init():
    actor = make_nets()[0]
    encoder = get_policy_encoder(actor)
    linears = [m for m in actor.modules() if isinstance(m, torch.nn.Linear)]
    assert len(linears) == len(HIDDEN) + 1
    for layer in linears:  # orthogonal weights (gain 1), zero biases
        w = layer.weight.detach()
        small = w @ w.T if w.shape[0] <= w.shape[1] else w.T @ w
        torch.testing.assert_close(small, torch.eye(small.shape[0]), atol=1e-5, rtol=0)
        assert not layer.bias.detach().any()
    spec = action_spec()
    low, high = spec.space.low, spec.space.high
    obs = torch.randn(8, OBS, generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        z = obs
        for layer in linears[:-1]:
            z = torch.relu(layer(z))
        expected = low + (torch.tanh(linears[-1](z)) + 1) * (high - low) / 2
        td = actor(TensorDict(observation=obs, batch_size=[8]))
    torch.testing.assert_close(td["embedding"], z)
    torch.testing.assert_close(td["action"], expected)
    assert {id(p) for p in encoder.parameters()} == {id(p) for p in linears[0].parameters()} | {
        id(p) for p in linears[1].parameters()
    }
    with pytest.raises(ValueError, match="hidden"):
        build_deterministic_actor(OBS, spec, ())
    with pytest.raises(ValueError, match="sigma"):
        build_ddpg_exploration(actor, spec, sigma=-0.1)
