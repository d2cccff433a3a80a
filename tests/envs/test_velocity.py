"""The velocity tasks against Safety-Gymnasium's rule and Gymnasium's plain v4 robots."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import s3rl_torchrl  # noqa: F401  (registers the tasks)
from s3rl_torchrl.envs import VELOCITY_REGISTRATIONS, VELOCITY_TASKS, get_task, task_names

# Safety-Gymnasium 1.0's thresholds and cost velocity, copied from the shared reference notes
# (§1) rather than from the package registry, so the registry is checked against them.
REFERENCE = {
    ("Ant", "v0"): (2.5745, "xy"),
    ("Ant", "v1"): (2.6222, "xy"),
    ("HalfCheetah", "v0"): (2.8795, "x"),
    ("HalfCheetah", "v1"): (3.2096, "x"),
    ("Hopper", "v0"): (0.37315, "x"),
    ("Hopper", "v1"): (0.7402, "x"),
    ("Humanoid", "v0"): (2.3475, "xy"),
    ("Humanoid", "v1"): (1.4149, "xy"),
    ("Swimmer", "v0"): (0.04845, "xy"),
    ("Swimmer", "v1"): (0.2282, "x"),
    ("Walker2d", "v0"): (1.7075, "x"),
    ("Walker2d", "v1"): (2.3415, "x"),
}
OBS_DIM_V4 = {"Ant": 27, "HalfCheetah": 17, "Hopper": 11, "Humanoid": 376, "Swimmer": 8, "Walker2d": 17}


def reference_cost(info: dict, robot: str, version: str) -> float:
    threshold, speed = REFERENCE[(robot, version)]
    if speed == "x":
        velocity = info["x_velocity"]
    else:
        velocity = math.sqrt(info["x_velocity"] ** 2 + info["y_velocity"] ** 2)
    return 1.0 if velocity > threshold else 0.0


def test_registry_matches_reference_table():
    assert {(t.robot, t.version): (t.threshold, t.speed) for t in VELOCITY_TASKS} == REFERENCE
    for task in VELOCITY_TASKS:
        assert task.obs_dim == OBS_DIM_V4[task.robot]


@pytest.mark.parametrize("robot,version", sorted(REFERENCE))
def test_ids_registered_with_time_limit(robot, version):
    for env_id in (
        f"Safety{robot}Velocity-{version}",
        f"Safety{robot}VelocityGymnasium-{version}",
        f"Safety{robot}VelocityMujocoV5-{version}",
    ):
        assert env_id in gym.registry
        assert gym.spec(env_id).max_episode_steps == 1000
        assert env_id in task_names()


def _random_actions(space: gym.spaces.Box, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(space.low, space.high, size=(n, *space.shape)).astype(space.dtype)


def _rollout_pair(task_id: str, base_id: str, steps: int, seed: int, **task_kwargs):
    """Step the safety task and its base robot with the same seed and actions."""
    safe_env, base_env = gym.make(task_id, **task_kwargs), gym.make(base_id)
    obs_s, _ = safe_env.reset(seed=seed)
    obs_b, _ = base_env.reset(seed=seed)
    np.testing.assert_array_equal(obs_s, obs_b)
    for action in _random_actions(safe_env.action_space, steps, seed):
        out_s, out_b = safe_env.step(action), base_env.step(action)
        np.testing.assert_array_equal(out_s[0], out_b[0])
        assert out_s[1:4] == out_b[1:4]  # reward, terminated, truncated
        yield out_s[4], out_b[4]
        if out_s[2] or out_s[3]:
            break


def reference_velocity(info: dict, speed: str) -> float:
    if speed == "x":
        return info["x_velocity"]
    return math.sqrt(info["x_velocity"] ** 2 + info["y_velocity"] ** 2)


@pytest.mark.parametrize("robot,version", sorted(REFERENCE))
def test_cost_follows_threshold_rule_and_robot_is_unchanged(robot, version):
    task = VELOCITY_REGISTRATIONS[f"Safety{robot}Velocity-{version}"].task
    for info_s, info_b in _rollout_pair(task.env_id, f"{robot}-v4", steps=150, seed=7):
        assert info_s["cost"] == reference_cost(info_b, robot, version)
        # The graded margin (threshold - speed) is negative exactly when the step costs.
        speed = reference_velocity(info_b, task.speed)
        assert info_s["cost_margin"] == pytest.approx(task.threshold - speed, abs=1e-12)
        assert (info_s["cost_margin"] < 0) == (info_s["cost"] == 1.0)
        added = ("cost", "cost_margin")
        assert {k: v for k, v in info_s.items() if k not in added} == info_b


@pytest.mark.parametrize("robot,version", sorted(REFERENCE))
def test_cost_reads_the_right_velocity(robot, version):
    # Random actions rarely cross the real limits, so the cost above is mostly 0. Here the
    # limit is moved to the median speed of the same rollout, so both labels occur and a wrong
    # velocity (signed x vs planar speed, wrong body) would show.
    _, speed = REFERENCE[(robot, version)]
    task_id = f"Safety{robot}Velocity-{version}"
    speeds = [
        reference_velocity(info_b, speed)
        for _, info_b in _rollout_pair(task_id, f"{robot}-v4", steps=100, seed=3)
    ]
    threshold = float(np.median(speeds))
    costs = []
    for info_s, info_b in _rollout_pair(
        task_id, f"{robot}-v4", steps=100, seed=3, cost_threshold=threshold
    ):
        assert info_s["cost"] == float(reference_velocity(info_b, speed) > threshold)
        costs.append(info_s["cost"])
    assert 0.0 in costs and 1.0 in costs


def test_strict_threshold_and_signed_velocity():
    from s3rl_torchrl.envs import velocity_cost

    assert velocity_cost({"x_velocity": 3.2096}, 3.2096, "x") == 0.0  # strict '>'
    assert velocity_cost({"x_velocity": 3.2097}, 3.2096, "x") == 1.0
    assert velocity_cost({"x_velocity": -10.0}, 3.2096, "x") == 0.0  # backwards never costs
    assert velocity_cost({"x_velocity": -0.3, "y_velocity": 0.4}, 0.45, "xy") == 1.0
    assert velocity_cost({"x_velocity": -0.3, "y_velocity": 0.4}, 0.5, "xy") == 0.0
    with pytest.raises(ValueError, match="'x' and 'xy'"):
        velocity_cost({"x_velocity": 1.0}, 0.5, "z")


def test_swimmer_v1_uses_forward_velocity_only():
    # A sideways-only Swimmer move costs under v0 (planar speed) but not under v1 (x only).
    info = {"x_velocity": 0.0, "y_velocity": 1.0}
    from s3rl_torchrl.envs import velocity_cost

    v0 = VELOCITY_REGISTRATIONS["SafetySwimmerVelocity-v0"].task
    v1 = VELOCITY_REGISTRATIONS["SafetySwimmerVelocity-v1"].task
    assert velocity_cost(info, v0.threshold, v0.speed) == 1.0
    assert velocity_cost(info, v1.threshold, v1.speed) == 0.0


@pytest.mark.parametrize("env_id", ["SafetyHalfCheetahVelocityMujocoV5-v1", "SafetyAntVelocityMujocoV5-v1"])
def test_v5_variant_runs_on_v5_robot(env_id):
    registered = VELOCITY_REGISTRATIONS[env_id]
    assert registered.mujoco_version == "v5"
    env = gym.make(env_id)
    base = gym.make(registered.task.base_env_id("v5"))
    assert env.observation_space.shape == base.observation_space.shape
    for info_s, info_b in _rollout_pair(env_id, registered.task.base_env_id("v5"), 20, seed=1):
        assert info_s["cost"] == reference_cost(info_b, registered.task.robot, registered.task.version)


def test_half_cheetah_truncates_at_1000_steps():
    env = gym.make("SafetyHalfCheetahVelocity-v1")
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    for t in range(1, 1001):
        _, _, terminated, truncated, _ = env.step(zero)
        assert not terminated
        assert truncated == (t == 1000)


def test_unknown_task_lists_valid_names():
    with pytest.raises(ValueError, match="SafetyHalfCheetahVelocity-v1") as err:
        get_task("SafetyCheetahVelocity-v1")
    assert "Unknown task 'SafetyCheetahVelocity-v1'" in str(err.value)
