"""Critic diagnostics: episodes kept across batches, returns and calibration by hand."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict

from s3rl_torchrl.diagnostics.critics import (
    RecentEpisodes,
    actor_gradient_norms,
    critic_calibration,
    discounted_returns,
)


def batch(envs: int, steps: int, done_at: dict[int, list[int]], start: int = 0) -> TensorDict:
    """``[envs, steps]`` frames whose observation is the global step index ``start + t``."""
    t = torch.arange(start, start + steps, dtype=torch.float32)
    done = torch.zeros(envs, steps, 1, dtype=torch.bool)
    for env, ends in done_at.items():
        done[env, ends] = True
    return TensorDict(
        {
            "observation": t.expand(envs, steps).unsqueeze(-1).clone(),
            "action": torch.zeros(envs, steps, 1),
            "next": {
                "reward": torch.ones(envs, steps, 1),
                "cost": torch.zeros(envs, steps, 1),
                "done": done,
                "terminated": done.clone(),
            },
        },
        [envs, steps],
    )


def test_episodes_are_joined_across_batches_and_only_finished_ones_kept():
    recent = RecentEpisodes(capacity=3)
    recent.extend(batch(2, 5, {0: [2]}))  # env 0 ends at 2; both carry the rest
    assert [ep["observation"].flatten().tolist() for ep in recent.episodes] == [[0, 1, 2]]
    recent.extend(batch(2, 5, {0: [1], 1: [4]}, start=5))
    got = [ep["observation"].flatten().tolist() for ep in recent.episodes]
    assert got == [[0, 1, 2], [3, 4, 5, 6], list(range(10))]
    recent.extend(batch(2, 5, {0: [0, 4]}, start=10))  # capacity 3: the oldest goes
    got = [ep["observation"].flatten().tolist() for ep in recent.episodes]
    assert got == [list(range(10)), [7, 8, 9, 10], [11, 12, 13, 14]]


def test_state_dict_round_trip_keeps_unfinished_steps():
    recent = RecentEpisodes(capacity=2)
    recent.extend(batch(1, 4, {0: [1]}))
    restored = RecentEpisodes()
    restored.load_state_dict(recent.state_dict())
    restored.extend(batch(1, 3, {0: [0]}, start=4))
    got = [ep["observation"].flatten().tolist() for ep in restored.episodes]
    assert got == [[0, 1], [2, 3, 4]]


def test_discounted_returns_by_hand():
    signal = torch.tensor([1.0, 0.0, 2.0])
    gamma = 0.5
    # Terminated: nothing after the last step.
    expected = [1 + 0.5 * 0 + 0.25 * 2, 0 + 0.5 * 2, 2.0]
    assert discounted_returns(signal, gamma, terminated=True).tolist() == pytest.approx(expected)
    # Time limit: the tail continues at the mean of the last ceil(1 / (1 - gamma)) = 2 steps.
    tail = (0.0 + 2.0) / 2 / (1 - gamma)
    expected = [e + gamma ** (3 - t) * tail for t, e in enumerate(expected)]
    assert discounted_returns(signal, gamma, terminated=False).tolist() == pytest.approx(expected)


class ConstantCritics:
    """A stand-in loss: reward critics (2, 3) and cost critics (-1, 4) everywhere."""

    cost_nonnegative = False

    def critic_values(self, td):
        n = td.shape[0]
        return torch.tensor([[2.0], [3.0]]).expand(2, n), torch.tensor([[[-1.0], [4.0]]]).expand(
            1, 2, n
        )

    def read_cost(self, q_cost):
        return q_cost.max(1)[0]


def test_calibration_by_hand():
    episode = batch(1, 3, {0: [2]})[0]
    episode["next", "cost"] = torch.tensor([[1.0], [0.0], [1.0]])
    out = critic_calibration(ConstantCritics(), [episode], gamma=0.5)
    reward_returns = [1 + 0.5 + 0.25, 1 + 0.5, 1.0]
    cost_returns = [1 + 0.25, 0.5, 1.0]
    assert out["critic/reward_q"] == pytest.approx(2.0)  # min of the reward pair
    assert out["critic/cost_q"] == pytest.approx(4.0)  # the loss's read (max here)
    assert out["critic/reward_return"] == pytest.approx(sum(reward_returns) / 3)
    assert out["critic/cost_error"] == pytest.approx(4.0 - sum(cost_returns) / 3)
    rmse = math.sqrt(sum((4.0 - c) ** 2 for c in cost_returns) / 3)
    assert out["critic/cost_rmse"] == pytest.approx(rmse)


def test_calibration_without_episodes_is_nan():
    out = critic_calibration(ConstantCritics(), [], gamma=0.99)
    assert all(math.isnan(v) for v in out.values())


def test_gradient_norms_match_autograd_of_each_term():
    from tests.objectives.test_sac_lag import make_batch, make_loss

    loss, *_ = make_loss(1, entropy_rescaling=False, cost_critic_read="max")
    loss.lagrangian = 0.5
    data = make_batch()
    torch.manual_seed(3)
    norms = actor_gradient_norms(loss, data.clone())
    torch.manual_seed(3)
    terms = loss.actor_loss_terms(data.clone())
    params = list(loss.actor_network_params.values(True, True))
    for name, term in terms.items():
        grads = torch.autograd.grad(term, params, retain_graph=True)
        expected = torch.sqrt(sum(g.square().sum() for g in grads))
        assert norms[f"grad/{name}"] == pytest.approx(float(expected), rel=1e-5)
    assert norms["grad/cost"] > 0
