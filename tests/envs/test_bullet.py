"""The Bullet-Safety-Gym tasks through make_env against the plain upstream package."""

from __future__ import annotations

import importlib
import sys
import warnings
from contextlib import contextmanager

import gymnasium as gym
import numpy as np
import pytest
import torch

from s3rl_torchrl.envs import BULLET_TASKS, get_task, make_env, task_names
from tests.envs._policies import ReplayActions

pytest.importorskip("pybullet")  # the `bullet` extra; `make setup` installs it

BULLET_IDS = [spec.env_id for spec in BULLET_TASKS]
# The paper's Bullet tasks (Table 1 and Figure 2 of the S3RL paper).
PAPER_BULLET_IDS = {
    f"Safety{robot}{task}-v0" for robot in ("Ball", "Car", "Drone", "Ant") for task in ("Run", "Circle")
}


@contextmanager
def real_std_streams():
    # bullet-safety-gym flushes C's stdout/stderr by the Python stream's name, which pytest's
    # capture replaces: the plain upstream env is imported and built with the real streams.
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = sys.__stdout__, sys.__stderr__
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved


@pytest.fixture(scope="module")
def upstream():
    with real_std_streams():
        return importlib.import_module("bullet_safety_gym")


def plain_env(env_id: str) -> gym.Env:
    """The upstream env exactly as `gymnasium.make` builds it from its own registration."""
    with real_std_streams(), warnings.catch_warnings():
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        return gym.make(env_id)


def test_registry_lists_the_paper_bullet_tasks():
    assert set(BULLET_IDS) == PAPER_BULLET_IDS
    assert set(BULLET_IDS) <= set(task_names(include_variants=False, include_aliases=False))
    for spec in BULLET_TASKS:
        assert spec.family == "bullet" and spec.extra == "bullet"
        assert spec.cost_limit == 10.0  # the paper's Table 3 default
        assert spec.registered_as == f"s3rl_torchrl/{spec.env_id}"


@pytest.mark.parametrize("env_id", BULLET_IDS)
def test_registry_facts_match_the_installed_package(env_id, upstream):
    spec = get_task(env_id)
    upstream_spec = gym.spec(env_id)
    assert upstream_spec.entry_point == "bullet_safety_gym.envs.builder:EnvironmentBuilder"
    assert spec.max_episode_steps == upstream_spec.max_episode_steps
    assert gym.spec(spec.registered_as).max_episode_steps == upstream_spec.max_episode_steps
    env = plain_env(env_id)
    assert env.observation_space.shape == (spec.obs_dim,)
    assert env.action_space.shape == (spec.act_dim,)
    # The cost rule written in the registry (and docs/tasks.md) names upstream's own limits.
    task, agent = env.unwrapped.task, env.unwrapped.agent
    if "Run" in env_id:
        assert type(task).__name__ == "RunTask"
        expected = f"1 if |y| > {task.y_lim:g} or sqrt(vx^2 + vy^2) > {agent.velocity_constraint:g}"
    else:
        assert type(task).__name__ == "CircleTask"
        expected = f"1 if |x| > {task.x_lim:g}"
    assert spec.cost_rule == expected
    env.close()


def _actions(spec, steps: int, seed: int) -> np.ndarray:
    # Mostly forward with noise: fast enough that the Ball and Car Run tasks pay speed costs.
    rng = np.random.default_rng(seed)
    actions = 0.7 + 0.5 * rng.standard_normal((steps, spec.act_dim))
    return np.clip(actions, -1.0, 1.0).astype(np.float32)


def _plain_rollout(env_id: str, actions: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    """Drive the plain upstream env; seeded the way upstream is: NumPy's global generator.

    torchrl's ``set_seed`` resets once with the seed and the rollout resets again, so the
    reference resets twice too; an episode that ends is followed by a reset.
    """
    env = plain_env(env_id)
    np.random.seed(seed)
    env.reset()
    obs, _ = env.reset()
    out = {k: [] for k in ("observation", "reward", "cost", "terminated", "truncated")}
    for action in actions:
        out["observation"].append(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        out["reward"].append(reward)
        out["cost"].append(info["cost"])
        out["terminated"].append(terminated)
        out["truncated"].append(truncated)
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    return {k: np.asarray(v) for k, v in out.items()}


# BallRun runs past its 100-step time limit (truncation and the reset after it); the others
# 60 steps (PyBullet steps cost a few ms each).
@pytest.mark.parametrize("env_id", BULLET_IDS)
def test_make_env_equals_plain_upstream_env(env_id, upstream):
    spec = get_task(env_id)
    steps = spec.max_episode_steps + 5 if env_id == "SafetyBallRun-v0" else 60
    seed = 3
    actions = _actions(spec, steps, seed=11)
    # Global NumPy state is scrambled first: make_env's envs must not depend on it.
    np.random.seed(12345)
    env = make_env(env_id, seed=seed)
    ours = env.rollout(steps, ReplayActions(actions), break_when_any_done=False)
    ref = _plain_rollout(env_id, actions, seed)
    torch.testing.assert_close(
        ours["observation"], torch.as_tensor(ref["observation"]).float(), rtol=0, atol=0
    )
    torch.testing.assert_close(
        ours["next", "reward"].squeeze(-1), torch.as_tensor(ref["reward"]).float(), rtol=0, atol=0
    )
    assert ours["next", "cost"].squeeze(-1).tolist() == ref["cost"].astype(float).tolist()
    assert ours["next", "terminated"].squeeze(-1).tolist() == ref["terminated"].tolist()
    assert ours["next", "truncated"].squeeze(-1).tolist() == ref["truncated"].tolist()
    if env_id == "SafetyBallRun-v0":
        assert ref["truncated"].nonzero()[0].tolist() == [spec.max_episode_steps - 1]
        assert ref["cost"].sum() > 0  # the speed limit is exceeded: both labels occur
    env.close()


def test_cost_label_episode_sums_and_batched_copies():
    env = make_env("SafetyBallRun-v0", num_envs=2, seed=0)
    actions = torch.ones(50, 2, 2)
    td = env.rollout(50, ReplayActions(actions), break_when_any_done=False)
    cost = td["next", "cost"]
    assert cost.shape == td["next", "reward"].shape == (2, 50, 1)
    assert td["observation"].dtype == torch.float32
    assert 0 < cost.sum() < cost.numel()
    torch.testing.assert_close(td["next", "safe"], cost == 0)
    torch.testing.assert_close(td["next", "episode_cost"], cost.cumsum(1))
    # The two copies are seeded apart: different starts.
    assert not torch.equal(td["observation"][0, 0], td["observation"][1, 0])
    env.close()


def test_seeded_envs_repeat_and_steps_leave_numpy_global_state_alone():
    a = make_env("SafetyCarCircle-v0", seed=7)
    np.random.seed(1)
    b = make_env("SafetyCarCircle-v0", seed=7)
    c = make_env("SafetyCarCircle-v0", seed=8)
    ra, rb, rc = a.reset(), b.reset(), c.reset()
    torch.testing.assert_close(ra["observation"], rb["observation"], rtol=0, atol=0)
    assert not torch.equal(ra["observation"], rc["observation"])
    # Resets draw from the env's own generator and steps draw nothing: the global state is as
    # the test left it.
    np.random.seed(99)
    before = np.random.get_state()[1].copy()
    a.reset()
    a.rollout(5)
    assert np.array_equal(np.random.get_state()[1], before)


def test_plain_gymnasium_id_of_this_package(upstream):
    # `gymnasium.make("s3rl_torchrl/SafetyBallRun-v0")` is the upstream env, seedable by reset.
    spec = get_task("SafetyBallRun-v0")
    env = gym.make(spec.registered_as)
    first, _ = env.reset(seed=4)
    again, _ = env.reset(seed=4)
    np.testing.assert_array_equal(first, again)
    assert env.spec.max_episode_steps == spec.max_episode_steps
    env.close()
