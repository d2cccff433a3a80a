"""``CostToGo``: the discounted cost-to-go label against hand computations."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.transforms import COST_TO_GO_KEY, CostToGo, discounted_cost_to_go


def batch(cost, done) -> TensorDict:
    """A collected batch ``[*env, T]`` with ``("next", "cost")`` and ``("next", "done")``."""
    cost = torch.as_tensor(cost, dtype=torch.float32)
    done = torch.as_tensor(done, dtype=torch.bool)
    if cost.ndim == done.ndim:
        cost = cost[..., None]
    return TensorDict(
        {"next": {"cost": cost, "done": done[..., None]}}, batch_size=done.shape
    )


def test_hand_computation_episode_end_inside_the_batch_and_cut_at_its_end():
    # Episode 1 is steps 0..2 (done at 2); episode 2 starts at 3 and runs past the batch end.
    # gamma = 0.5, by hand:
    #   G2 = 0                 G1 = 1 + 0.5 * 0 = 1       G0 = 0 + 0.5 * 1 = 0.5
    #   G5 = 1 (truncated)     G4 = 1 + 0.5 * 1 = 1.5     G3 = 0 + 0.5 * 1.5 = 0.75
    data = batch([0, 1, 0, 0, 1, 1], [0, 0, 1, 0, 0, 0])
    CostToGo(0.5, complete_key=("next", "cost_to_go_complete"))(data)
    assert data[COST_TO_GO_KEY].squeeze(-1).tolist() == [0.5, 1.0, 0.0, 0.75, 1.5, 1.0]
    assert data[COST_TO_GO_KEY].dtype == torch.float32
    complete = data["next", "cost_to_go_complete"].squeeze(-1).tolist()
    assert complete == [True, True, True, False, False, False]


def test_a_batch_that_cuts_an_episode_is_truncated_at_its_end():
    # One 8-step episode collected as two batches of 4: each batch's labels sum its own steps
    # only (documented truncation), and the first batch is short by exactly
    # gamma^(4 - t) * G_4 of the whole episode.
    gamma = 0.8
    cost = [1, 0, 0, 1, 1, 0, 1, 0]
    done = [0, 0, 0, 0, 0, 0, 0, 1]
    whole = [sum(gamma**k * c for k, c in enumerate(cost[t:])) for t in range(8)]
    first = CostToGo(gamma)(batch(cost[:4], done[:4]))[COST_TO_GO_KEY].squeeze(-1)
    second = CostToGo(gamma)(batch(cost[4:], done[4:]))[COST_TO_GO_KEY].squeeze(-1)
    by_hand_first = [sum(gamma**k * c for k, c in enumerate(cost[t:4])) for t in range(4)]
    assert first.tolist() == pytest.approx(by_hand_first, abs=1e-6)
    assert second.tolist() == pytest.approx(whole[4:], abs=1e-6)  # this batch sees the end
    missing = [whole[t] - by_hand_first[t] for t in range(4)]
    assert missing == pytest.approx([gamma ** (4 - t) * whole[4] for t in range(4)], abs=1e-6)


def test_env_copies_are_independent_and_several_costs_are_summed():
    gamma = 0.9
    # Env 0: two costs per step, no episode end. Env 1: an episode ends at step 1.
    cost = torch.tensor(
        [[[1.0, 0.0], [0.0, 0.0], [0.0, 2.0]], [[0.0, 0.0], [1.0, 1.0], [3.0, 0.0]]]
    )
    done = torch.tensor([[False, False, False], [False, True, False]])
    data = TensorDict({"next": {"cost": cost, "done": done[..., None]}}, batch_size=[2, 3])
    label = CostToGo(gamma)(data)[COST_TO_GO_KEY]
    assert label.shape == (2, 3, 1)
    expected = [
        [1.0 + gamma**2 * 2.0, gamma * 2.0, 2.0],
        [gamma * 2.0, 2.0, 3.0],
    ]
    assert label.squeeze(-1).tolist() == [pytest.approx(row, abs=1e-6) for row in expected]


@pytest.mark.parametrize("seed", [0, 1])
def test_function_matches_a_plain_loop_on_random_episodes(seed):
    generator = torch.Generator().manual_seed(seed)
    cost = (torch.rand(3, 40, 1, generator=generator) < 0.3).float()
    done = torch.rand(3, 40, 1, generator=generator) < 0.1
    gamma = 0.7
    got = discounted_cost_to_go(cost, done, gamma)
    for env in range(3):
        for t in range(40):
            total, discount = 0.0, 1.0
            for k in range(t, 40):  # forward, to the episode's end or the batch end
                total += discount * float(cost[env, k, 0])
                discount *= gamma
                if done[env, k, 0]:
                    break
            assert float(got[env, t, 0]) == pytest.approx(total, abs=1e-5)


def test_gamma_zero_is_the_step_cost():
    data = batch([0, 2, 1, 0], [0, 0, 0, 1])
    assert CostToGo(0.0)(data)[COST_TO_GO_KEY].squeeze(-1).tolist() == [0, 2, 1, 0]


def test_replay_buffer_transform_labels_on_extend():
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10))
    rb.append_transform(CostToGo(0.5))
    rb.extend(batch([1, 1, 0, 1], [0, 1, 0, 0]))
    stored = rb.storage[:4]
    assert stored[COST_TO_GO_KEY].squeeze(-1).tolist() == [1.5, 1.0, 0.5, 1.0]


def test_errors():
    with pytest.raises(ValueError, match="gamma"):
        CostToGo(1.0)
    with pytest.raises(KeyError, match="cost"):
        CostToGo()(TensorDict({"next": {"done": torch.zeros(3, 1, dtype=torch.bool)}}, [3]))
    with pytest.raises(ValueError, match="time dimension"):
        CostToGo()(TensorDict({"next": {"cost": torch.zeros(1), "done": torch.zeros(1)}}, []))
    with pytest.raises(ValueError, match="not inside an env"):
        CostToGo()._call(TensorDict({}, []))
