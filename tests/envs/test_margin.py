"""The graded safety margins: by hand, and consistent with the binary cost on env data."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from s3rl_torchrl.envs import get_task, make_env, task_names
from s3rl_torchrl.envs.goal import hazard_cost, hazard_margin
from s3rl_torchrl.envs.velocity import velocity_cost, velocity_margin


def test_velocity_margin_by_hand():
    info = {"x_velocity": 2.0, "y_velocity": -1.5}
    assert velocity_margin(info, 3.0, "x") == pytest.approx(1.0)
    assert velocity_margin(info, 3.0, "xy") == pytest.approx(3.0 - 2.5)
    fast = {"x_velocity": 3.5}
    assert velocity_margin(fast, 3.0, "x") == pytest.approx(-0.5)
    assert velocity_cost(fast, 3.0, "x") == 1.0
    at_limit = {"x_velocity": 3.0}
    assert velocity_margin(at_limit, 3.0, "x") == 0.0 and velocity_cost(at_limit, 3.0, "x") == 0.0


def test_hazard_margin_by_hand():
    hazards = np.array([[1.0, 0.0], [0.0, 3.0]])
    assert hazard_margin(np.array([0.0, 0.0]), hazards) == pytest.approx(1.0 - 0.2)
    inside = np.array([0.9, 0.0])  # 0.1 from the first hazard's centre
    assert hazard_margin(inside, hazards) == pytest.approx(-0.1)
    assert hazard_cost(inside, hazards) == 1.0


def test_every_margin_task_is_velocity_or_goal():
    having = {get_task(n).family for n in task_names() if get_task(n).margin_rule}
    assert having == {"velocity", "goal"}


@pytest.mark.parametrize("task", ["SafetyHalfCheetahVelocity-v1", "SafetyPointGoal1-v0"])
def test_env_margin_is_negative_exactly_when_the_step_costs(task):
    torch.manual_seed(0)
    env = make_env(task, num_envs=2, seed=3, margin=True)
    data = env.rollout(200, break_when_any_done=False)
    margin, cost = data["next", "margin"], data["next", "cost"]
    assert margin.shape == cost.shape and margin.dtype == torch.float32
    assert torch.equal(margin < 0, cost > 0)
    assert torch.isnan(data["margin"][:, 0]).all()  # a reset has no margin
    assert data["observation"].shape[-1] == get_task(task).obs_dim  # not in the observation
    env.close()


def test_margin_is_refused_for_a_task_without_one():
    with pytest.raises(ValueError, match="exposes no graded safety margin"):
        make_env("SafetyCarCircle-v0", margin=True)


def test_no_margin_entry_by_default():
    env = make_env("SafetyHalfCheetahVelocity-v1", num_envs=1, seed=0)
    assert ("next", "margin") not in env.rollout(2).keys(True)
