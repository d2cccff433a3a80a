"""n-step transitions against hand-written windows (termination, truncation, buffering)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, ReplayBuffer

from s3rl_torchrl.transforms import NStepTransform, make_nstep_transform, nstep_transition

GAMMA = 0.5  # powers of 1/2 keep the hand sums exact in float32


def trajectory(T: int = 10, terminated_at=(3,), truncated_at=(7,)) -> TensorDict:
    """One env copy: obs_t = t, next obs = 100 + t + 1, r_t = t + 1, c_t = 10 (t + 1)."""
    terminated = torch.zeros(T, 1, dtype=torch.bool)
    truncated = torch.zeros(T, 1, dtype=torch.bool)
    terminated[list(terminated_at)] = True
    truncated[list(truncated_at)] = True
    t = torch.arange(T, dtype=torch.float32)[:, None]
    return TensorDict(
        {
            "observation": t.clone(),
            "next": {
                "observation": 101 + t,
                "reward": t + 1,
                "cost": 10 * (t + 1),
                "safe": (torch.arange(T) % 2 == 0)[:, None],
                "terminated": terminated,
                "truncated": truncated,
                "done": terminated | truncated,
            },
        },
        [T],
    )


def test_two_step_windows_by_hand():
    out = nstep_transition(trajectory(), 2, GAMMA)
    # t:         0    1    2    3    4    5    6    7    8    9
    # window:   0-1  1-2  2-3  3    4-5  5-6  6-7  7    8-9  9 (end of data)
    # t=2 stops at the termination (3), t=6 at the truncation (7).
    reward = [
        1 + 2 / 2,
        2 + 3 / 2,
        3 + 4 / 2,
        4,
        5 + 6 / 2,
        6 + 7 / 2,
        7 + 8 / 2,
        8,
        9 + 10 / 2,
        10,
    ]
    steps = [2, 2, 2, 1, 2, 2, 2, 1, 2, 1]
    end = [1, 2, 3, 3, 5, 6, 7, 7, 9, 9]  # step whose next observation is bootstrapped
    assert out["next", "reward"].squeeze(-1).tolist() == reward
    assert out["next", "cost"].squeeze(-1).tolist() == [10 * r for r in reward]
    assert out["steps_to_next_obs"].tolist() == steps
    assert out["next", "observation"].squeeze(-1).tolist() == [101.0 + e for e in end]
    terminated = [e == 3 for e in end]
    truncated = [e == 7 for e in end]
    assert out["next", "terminated"].squeeze(-1).tolist() == terminated
    assert out["next", "truncated"].squeeze(-1).tolist() == truncated
    assert out["next", "done"].squeeze(-1).tolist() == [
        a or b for a, b in zip(terminated, truncated)
    ]
    # One-step values kept; labels of step t stay at t; the root is untouched.
    assert out["next", "reward_orig"].squeeze(-1).tolist() == list(range(1, 11))
    assert out["next", "cost_orig"].squeeze(-1).tolist() == [10.0 * r for r in range(1, 11)]
    assert out["next", "safe"].squeeze(-1).tolist() == [t % 2 == 0 for t in range(10)]
    assert out["observation"].squeeze(-1).tolist() == list(range(10))


def test_three_step_windows_by_hand():
    out = nstep_transition(trajectory(), 3, GAMMA)
    # t=1: 1-3 stops at the termination; t=5: 5-7 stops at the truncation.
    steps = [3, 3, 2, 1, 3, 3, 2, 1, 2, 1]
    reward = [
        1 + 2 / 2 + 3 / 4,
        2 + 3 / 2 + 4 / 4,
        3 + 4 / 2,
        4,
        5 + 6 / 2 + 7 / 4,
        6 + 7 / 2 + 8 / 4,
        7 + 8 / 2,
        8,
        9 + 10 / 2,
        10,
    ]
    assert out["steps_to_next_obs"].tolist() == steps
    assert out["next", "reward"].squeeze(-1).tolist() == reward
    assert out["next", "terminated"].squeeze(-1).tolist() == [
        False,
        True,
        True,
        True,
        False,
        False,
        False,
        False,
        False,
        False,
    ]


def test_n1_is_identity_plus_bookkeeping():
    data = trajectory()
    out = nstep_transition(data, 1, GAMMA)
    for key in ("reward", "cost", "observation", "terminated", "truncated", "done"):
        assert torch.equal(out["next", key], data["next", key])
    assert out["steps_to_next_obs"].tolist() == [1] * 10


def test_batched_envs_and_trailing_cost_dim():
    a, b = trajectory(6, (1,), ()), trajectory(6, (), (4,))
    data = torch.stack([a, b], 0)  # [2 envs, 6 steps], time last as a collector gives it
    data["next", "cost"] = torch.cat([data["next", "cost"], -data["next", "cost"]], -1)  # m = 2
    out = nstep_transition(data, 2, GAMMA)
    assert out["steps_to_next_obs"].tolist() == [[2, 1, 2, 2, 2, 1], [2, 2, 2, 2, 1, 1]]
    assert out["next", "reward"][0].squeeze(-1).tolist() == [2, 2, 3 + 2, 4 + 2.5, 5 + 3, 6]
    assert out["next", "cost"][1, :, 1].tolist() == [-20, -35, -50, -65, -50, -60]
    assert out["next", "terminated"][0].squeeze(-1).tolist() == [True, True] + [False] * 4


def test_replay_buffer_extend_in_chunks_matches_one_shot():
    data = trajectory()
    rb = ReplayBuffer(storage=LazyTensorStorage(50), transform=make_nstep_transform(2, GAMMA))
    rb.extend(data[:6])
    rb.extend(data[6:])
    stored = rb[:]
    # The transform holds back the last n steps of a batch until their future arrives.
    assert stored["observation"].squeeze(-1).tolist() == list(range(8))
    expected = nstep_transition(data, 2, GAMMA)[:8]
    for key in (
        ("next", "reward"),
        ("next", "cost"),
        ("next", "observation"),
        "steps_to_next_obs",
        ("next", "terminated"),
        ("next", "safe"),
    ):
        assert torch.equal(stored[key], expected[key]), key


def test_replay_buffer_with_batched_envs_stores_flat_transitions():
    data = torch.stack([trajectory(), trajectory(10, (5,), (8,))], 0)  # [2 envs, 10 steps]
    rb = ReplayBuffer(storage=LazyTensorStorage(50), transform=make_nstep_transform(2, GAMMA))
    rb.extend(data[:, :6])
    rb.extend(data[:, 6:])
    assert len(rb) == 16  # 2 envs x (10 - n) steps, one transition per row
    expected = nstep_transition(data, 2, GAMMA)
    # First extend: steps 0-3 of each env; second: steps 4-7.
    order = [(e, t) for chunk in (range(4), range(4, 8)) for e in range(2) for t in chunk]
    stored = rb[:]
    for row, (e, t) in enumerate(order):
        for key in (
            ("next", "reward"),
            ("next", "observation"),
            "steps_to_next_obs",
            ("next", "terminated"),
        ):
            assert torch.equal(stored[key][row], expected[key][e, t]), (key, e, t)


def test_make_nstep_transform_keys():
    transform = make_nstep_transform(2, 0.99, cost_key="c", reward_key="r", keep_keys=())
    assert isinstance(transform, NStepTransform)
    assert transform.reward_keys == ["r", "c"] and transform.keep_keys == ()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"n_steps": 0, "gamma": 0.9}, "n_steps"), ({"n_steps": 2, "gamma": 1.5}, "gamma")],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_nstep_transform(**kwargs)


def test_missing_reward_key_is_named():
    data = trajectory()
    del data["next", "cost"]
    with pytest.raises(KeyError, match="cost"):
        nstep_transition(data, 2, GAMMA)


def test_ending_the_held_episodes_cuts_their_windows_by_hand():
    # An episode cut after step 5 (e.g. a resume that restarts the envs): the next batch is a
    # new episode whose step_count starts again at 0.
    def counted(T):
        data = trajectory(T, terminated_at=(), truncated_at=())
        data["step_count"] = torch.arange(T)[:, None]
        return data

    as_it_was = ReplayBuffer(storage=LazyTensorStorage(50), transform=make_nstep_transform(2, GAMMA))
    as_it_was.extend(counted(6))
    with pytest.raises(ValueError, match="step_count jumps without an episode end"):
        as_it_was.extend(counted(4))  # the held windows would run into the new episode

    transform = make_nstep_transform(2, GAMMA)
    rb = ReplayBuffer(storage=LazyTensorStorage(50), transform=transform)
    rb.extend(counted(6))  # stores steps 0-3, holds 4 and 5
    transform.end_held_episodes()
    assert transform.held_frames["next", "truncated"].squeeze(-1).tolist() == [False, True]
    rb.extend(counted(4))
    stored = rb[:]
    # Steps 4 and 5 of the cut episode, then steps 0 and 1 of the new one (2 and 3 held).
    assert stored["observation"].squeeze(-1).tolist() == [0, 1, 2, 3, 4, 5, 0, 1]
    assert stored["next", "reward"].squeeze(-1).tolist()[4:6] == [5 + 6 / 2, 6]
    assert stored["steps_to_next_obs"].tolist()[4:6] == [2, 1]
    assert stored["next", "observation"].squeeze(-1).tolist()[4:6] == [106, 106]
    assert stored["next", "truncated"].squeeze(-1).tolist()[4:6] == [True, True]
    assert not stored["next", "terminated"].any()  # a cut, not a termination: bootstrapped
    # Before the first batch nothing is held: a no-op, not an error.
    fresh = make_nstep_transform(2, GAMMA)
    fresh.end_held_episodes()
    assert fresh.held_frames is None
