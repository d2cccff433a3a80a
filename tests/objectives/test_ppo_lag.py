"""PPOLagLoss against torchrl's ClipPPOLoss and against hand computations of FSRL's PPO-Lag."""

from __future__ import annotations

import copy

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ValueOperator
from torchrl.objectives import ClipPPOLoss

from s3rl_torchrl.modules import build_s3rl_actor
from s3rl_torchrl.objectives import PPOLagLoss
from tests.objectives._gradients import moved

OBS, ACT, HIDDEN, GAMMA, LMBDA, EPS = 4, 2, (16, 16), 0.9, 0.8, 0.2
SURROGATES = ("unclipped", "clipped")


def make_nets(seed: int = 0):
    torch.manual_seed(seed)
    spec = Bounded(-torch.ones(ACT), torch.ones(ACT), (ACT,))
    actor = build_s3rl_actor(OBS, spec, HIDDEN)
    critic = ValueOperator(MLP(in_features=OBS, out_features=1, num_cells=[16]), ["observation"])
    cost_critic = ValueOperator(
        MLP(in_features=OBS, out_features=1, num_cells=[16]),
        ["observation"],
        out_keys=["state_cost_value"],
    )
    return actor, critic, cost_critic


def make_loss(**kwargs):
    actor, critic, cost_critic = make_nets()
    loss = PPOLagLoss(actor, critic, cost_critic, clip_epsilon=EPS, **kwargs)
    loss.make_value_estimator(gamma=GAMMA, lmbda=LMBDA)
    return loss, actor, critic, cost_critic


def make_rollout(envs: int = 2, steps: int = 6, seed: int = 2) -> TensorDict:
    """``[envs, steps]`` of collected data: a termination and a truncation inside."""
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(envs, steps + 1, OBS, generator=g)
    terminated = torch.zeros(envs, steps, 1, dtype=torch.bool)
    done = torch.zeros(envs, steps, 1, dtype=torch.bool)
    terminated[0, 2] = done[0, 2] = True  # env 0 ends (terminal) at t = 2
    done[1, 4] = True  # env 1 is truncated at t = 4: bootstrap, but do not carry over
    td = TensorDict(
        {
            "observation": obs[:, :-1],
            "next": {
                "observation": obs[:, 1:],
                "reward": torch.randn(envs, steps, 1, generator=g),
                "cost": torch.rand(envs, steps, 1, generator=g),
                "terminated": terminated,
                "done": done,
            },
        },
        [envs, steps],
    )
    actor = make_nets()[0]
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        torch.manual_seed(seed)
        actor(td)
    # A behaviour policy slightly off the current one: ratios on both sides of the clip range.
    log_prob_key = actor.log_prob_keys[0]
    td[log_prob_key] = td[log_prob_key] + 0.4 * torch.randn(envs, steps, generator=g)
    return td


def gae_by_hand(reward, value, next_value, terminated, done, gamma=GAMMA, lmbda=LMBDA):
    """Reverse loop of the GAE recursion over the last (time) dimension."""
    advantage = torch.zeros_like(reward)
    running = torch.zeros_like(reward[:, 0])
    for t in reversed(range(reward.shape[1])):
        delta = reward[:, t] + gamma * (1 - terminated[:, t]) * next_value[:, t] - value[:, t]
        running = delta + gamma * lmbda * (1 - done[:, t]) * running
        advantage[:, t] = running
    return advantage


def test_cost_gae_by_hand():
    loss, _, critic, cost_critic = make_loss()
    td = make_rollout()
    loss.compute_advantages(td)
    with torch.no_grad():
        for net, reward_key, value_key, adv_key, target_key in (
            (cost_critic, "cost", "state_cost_value", "cost_advantage", "cost_value_target"),
            (critic, "reward", "state_value", "advantage", "value_target"),
        ):
            value = net(TensorDict(observation=td["observation"]))[value_key]
            next_value = net(TensorDict(observation=td["next", "observation"]))[value_key]
            expected = gae_by_hand(
                td["next", reward_key],
                value,
                next_value,
                td["next", "terminated"].float(),
                td["next", "done"].float(),
            )
            torch.testing.assert_close(td[adv_key], expected)
            torch.testing.assert_close(td[target_key], expected + value)


def standardize(x: torch.Tensor) -> torch.Tensor:
    return (x - x.mean()) / x.std()  # FSRL: per-minibatch, torch's (unbiased) std


@pytest.mark.parametrize("cost_surrogate", SURROGATES)
@pytest.mark.parametrize("rescaling", [True, False])
def test_penalised_policy_and_critic_losses_by_hand(cost_surrogate, rescaling):
    lagrangian = 0.7
    loss, actor, critic, cost_critic = make_loss(
        cost_surrogate=cost_surrogate, rescaling=rescaling, lagrangian_init=lagrangian
    )
    g = torch.Generator().manual_seed(5)
    batch = make_rollout().reshape(-1)
    n = batch.shape[0]
    # Advantages and targets given by hand: the loss must use them as they are.
    for key in ("advantage", "cost_advantage", "value_target", "cost_value_target"):
        batch[key] = torch.randn(n, 1, generator=g) * 3 + 1
    out = loss(batch.clone())

    dist = actor.get_dist(batch.select("observation"))
    log_prob = dist.log_prob(batch["action"])
    ratio = (log_prob - batch[actor.log_prob_keys[0]]).exp().unsqueeze(-1)
    assert bool((ratio > 1 + EPS).any()) and bool((ratio < 1 - EPS).any())
    adv_r, adv_c = standardize(batch["advantage"]), standardize(batch["cost_advantage"])
    scale = 1 + lagrangian if rescaling else 1.0
    clipped_ratio = ratio.clamp(1 - EPS, 1 + EPS)
    if cost_surrogate == "unclipped":  # FSRL
        reward_term = -torch.min(ratio * adv_r, clipped_ratio * adv_r).mean()
        expected = (reward_term + lagrangian * (ratio * adv_c).mean()) / scale
    else:  # OmniSafe
        adv = (adv_r - lagrangian * adv_c) / scale
        expected = -torch.min(ratio * adv, clipped_ratio * adv).mean()
    # The policy gradient too (the cost term must reach the actor through the ratio).
    actor_params = [p for p in actor.parameters() if p.requires_grad]
    for got, want in zip(
        torch.autograd.grad(out["loss_objective"], actor_params),
        torch.autograd.grad(expected, actor_params),
        strict=True,
    ):
        torch.testing.assert_close(got, want)
    with torch.no_grad():
        value = critic(batch.select("observation").clone())["state_value"]
        cost_value = cost_critic(batch.select("observation").clone())["state_cost_value"]
        expected_critic = 0.25 * ((value - batch["value_target"]) ** 2).mean()
        expected_cost_critic = 0.25 * ((cost_value - batch["cost_value_target"]) ** 2).mean()
    torch.testing.assert_close(out["loss_objective"], expected)
    torch.testing.assert_close(out["loss_critic"], expected_critic)
    torch.testing.assert_close(out["loss_cost_critic"], expected_cost_critic)
    torch.testing.assert_close(out["lagrangian"], torch.tensor([lagrangian]))


@pytest.mark.parametrize("cost_surrogate", SURROGATES)
def test_zero_lagrangian_matches_clipppoloss(cost_surrogate):
    loss, actor, critic, _ = make_loss(cost_surrogate=cost_surrogate)
    ref = ClipPPOLoss(
        copy.deepcopy(actor),
        copy.deepcopy(critic),
        clip_epsilon=EPS,
        entropy_bonus=False,
        critic_coeff=0.25,
        loss_critic_type="l2",
        normalize_advantage=True,
    )
    ref.make_value_estimator(gamma=GAMMA, lmbda=LMBDA)
    rollout = make_rollout()
    ours, theirs = rollout.clone(), rollout.clone()
    loss.compute_advantages(ours)
    ref.value_estimator(theirs)
    torch.testing.assert_close(ours["advantage"], theirs["advantage"])
    out, out_ref = loss(ours.reshape(-1)), ref(theirs.reshape(-1))
    for key in ("loss_objective", "loss_critic", "clip_fraction", "kl_approx"):
        torch.testing.assert_close(out[key], out_ref[key])
    (out["loss_objective"] + out["loss_critic"]).backward()
    (out_ref["loss_objective"] + out_ref["loss_critic"]).backward()
    for name in ("actor_network_params", "critic_network_params"):
        ours_p, ref_p = getattr(loss, name), getattr(ref, name)
        for key, p in ours_p.items(True, True):
            if p.requires_grad:
                torch.testing.assert_close(p.grad, ref_p.get(key).grad)


@pytest.mark.parametrize("cost_surrogate", SURROGATES)
def test_gradient_isolation(cost_surrogate):
    loss, *_ = make_loss(cost_surrogate=cost_surrogate, lagrangian_init=0.5)
    out = loss(make_rollout().reshape(-1))  # advantages computed inside the forward
    groups = {
        name: [p for p in params.values(True, True) if p.requires_grad]
        for name, params in (
            ("actor", loss.actor_network_params),
            ("critic", loss.critic_network_params),
            ("cost_critic", loss.cost_critic_network_params),
        )
    }

    assert moved(out["loss_objective"], groups) == {"actor": True, "critic": False, "cost_critic": False}
    assert moved(out["loss_critic"], groups) == {"actor": False, "critic": True, "cost_critic": False}
    assert moved(out["loss_cost_critic"], groups) == {
        "actor": False,
        "critic": False,
        "cost_critic": True,
    }


def test_the_cost_advantage_moves_the_policy_loss():
    """Same batch, two multipliers: only the cost term differs (guards against a dropped term)."""
    batch = make_rollout().reshape(-1)
    loss, *_ = make_loss()
    loss.compute_advantages(batch)
    at_zero = loss(batch.clone())["loss_objective"]
    loss.set_lagrangian(2.0)
    assert not torch.isclose(loss(batch.clone())["loss_objective"], at_zero)


def test_keys_arguments_and_lagrangian():
    loss, *_ = make_loss()
    assert ("next", "cost") in loss.in_keys
    assert {"loss_cost_critic", "lagrangian"} <= set(loss.out_keys)
    loss.lagrangian = 0.3
    torch.testing.assert_close(loss.lagrangian, torch.tensor([0.3]))
    with pytest.raises(ValueError, match="finite and >= 0"):
        loss.set_lagrangian(-0.1)
    actor, critic, cost_critic = make_nets()
    with pytest.raises(ValueError, match="cost_surrogate"):
        PPOLagLoss(actor, critic, cost_critic, cost_surrogate="both")
    td = make_rollout()
    td["next", "cost"] = torch.rand(*td.shape, 2)
    with pytest.raises(ValueError, match="one cost"):
        loss.compute_advantages(td)
