"""Safety-Gymnasium's Circle level-1 tasks: reward, cost and lidar recomputed by hand from the
simulator's joint state at every step of seeded rollouts; layout, resets, time limit, make_env.

The reference numbers are Safety-Gymnasium 1.0's (safety_gymnasium/tasks/safe_navigation/circle,
assets/geoms/{circle,sigwalls}.py, bases/base_task.py), written here again rather than imported,
so that the package's constants are checked against them.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation
from tensordict.nn import TensorDictModule
from torchrl.envs import DoubleToFloat, GymEnv, TransformedEnv, default_info_dict_reader

import s3rl_torchrl  # noqa: F401  (registers the tasks)
from s3rl_torchrl.envs import TASKS, get_task, make_env, task_names
from tests.envs._policies import ReplayActions

RADIUS, FACTOR, WALL, MAX_DIST, BINS = 1.5, 0.1, 1.125, 6.0, 16
OBS_DIM = {"Point": 28, "Car": 40}
IDS = {
    robot: (f"Safety{robot}Circle1-v0", f"Safety{robot}Circle1Gymnasium-v0")
    for robot in ("Point", "Car")
}
# Earth's field in MuJoCo's default options (mjOption.magnetic), what the magnetometer reads.
MAGNETIC = np.array([0.0, -0.5, 0.0])


def hand_reward(x, y, u, v):
    r = math.sqrt(x * x + y * y)
    tangential_speed = (-u * y + v * x) / r  # counter-clockwise speed around the origin
    return FACTOR * tangential_speed / (1 + abs(r - RADIUS))


def hand_lidar(ego_x, ego_y):
    """The 16 aliased pseudo-lidar bins of one point at (ego_x, ego_y) in the robot's frame."""
    bins = np.zeros(BINS)
    width = 2 * math.pi / BINS
    bearing = math.atan2(ego_y, ego_x) % (2 * math.pi)
    closeness = max(0.0, MAX_DIST - math.hypot(ego_x, ego_y)) / MAX_DIST
    k = int(bearing // width)
    fraction = bearing / width - k
    bins[k] = closeness
    bins[(k + 1) % BINS] = max(bins[(k + 1) % BINS], fraction * closeness)
    bins[(k - 1) % BINS] = max(bins[(k - 1) % BINS], (1 - fraction) * closeness)
    return bins


def robot_state(robot, data):
    """Body position, world velocity and world-from-body rotation, from qpos/qvel alone."""
    qpos, qvel = data.qpos, data.qvel
    if robot == "Point":  # joints: slide x, slide y (world axes), hinge yaw; body height 0.1
        position = np.array([qpos[0], qpos[1], 0.1])
        velocity = np.array([qvel[0], qvel[1], 0.0])
        rotation = Rotation.from_euler("z", qpos[2]).as_matrix()
    else:  # free joint: position, quaternion (w, x, y, z), world linear velocity
        position = qpos[0:3].copy()
        velocity = qvel[0:3].copy()
        w, x, y, z = qpos[3:7]
        rotation = Rotation.from_quat([x, y, z, w]).as_matrix()
    return position, velocity, rotation


def check_observation(robot, obs, data):
    position, velocity, rotation = robot_state(robot, data)
    assert obs.shape == (OBS_DIM[robot],) and obs.dtype == np.float64
    # Sensor block, Safety-Gymnasium's order: accelerometer, velocimeter, gyro, magnetometer.
    np.testing.assert_allclose(obs[3:6], rotation.T @ velocity, atol=1e-9)
    np.testing.assert_allclose(obs[9:12], rotation.T @ MAGNETIC, atol=1e-9)
    if robot == "Point":
        np.testing.assert_allclose(obs[6:9], [0.0, 0.0, data.qvel[2]], atol=1e-9)
    else:
        np.testing.assert_allclose(obs[6:9], data.qvel[3:6], atol=1e-9)  # free joint: body frame
        # Rear ball joint (qpos 9:13, qvel 8:11): angular velocity, then its rotation matrix.
        np.testing.assert_allclose(obs[12:15], data.qvel[8:11], atol=1e-9)
        w, x, y, z = data.qpos[9:13]
        ball = Rotation.from_quat([x, y, z, w]).as_matrix().reshape(-1)
        np.testing.assert_allclose(obs[15:24], ball, atol=1e-9)
    # Lidar of the circle's centre, the origin, seen from the robot body.
    ego = rotation.T @ (np.zeros(3) - position)
    lidar = obs[-BINS:]
    np.testing.assert_allclose(lidar, hand_lidar(ego[0], ego[1]), atol=1e-9)
    assert lidar.min() >= 0.0 and lidar.max() <= 1.0


def biased_actions(n, seed):
    """Mostly forward with random steering, so the robot crosses the walls within the rollout."""
    rng = np.random.default_rng(seed)
    return np.clip(np.array([0.7, 0.4]) + 0.6 * rng.standard_normal((n, 2)), -1.0, 1.0)


def test_registry_entries():
    assert set(task_names(family="circle")) == {i for ids in IDS.values() for i in ids}
    for robot, (main_id, paper_id) in IDS.items():
        for env_id in (main_id, paper_id):
            spec = get_task(env_id)
            assert spec.family == "circle" and spec.act_dim == 2
            assert spec.obs_dim == OBS_DIM[robot]
            assert spec.max_episode_steps == 500 == gym.spec(env_id).max_episode_steps
            assert spec.cost_limit == 10.0
        assert get_task(main_id).alias_of is None and get_task(paper_id).alias_of == main_id
    assert all(TASKS[i].env_id == i for ids in IDS.values() for i in ids)


@pytest.mark.parametrize("robot", ["Point", "Car"])
def test_reward_cost_and_observation_by_hand_every_step(robot):
    env = gym.make(IDS[robot][0])
    data = env.unwrapped.data
    assert env.observation_space.shape == (OBS_DIM[robot],)
    assert env.action_space.shape == (2,)
    np.testing.assert_array_equal(env.action_space.low, [-1, -1])
    np.testing.assert_array_equal(env.action_space.high, [1, 1])
    rewards, costs = [], []
    for episode, seed in enumerate((3, 4)):
        obs, info = env.reset(seed=seed)
        assert "cost" not in info
        check_observation(robot, obs, data)
        for action in biased_actions(150, seed=10 + episode):
            obs, reward, terminated, truncated, info = env.step(action)
            position, velocity, _ = robot_state(robot, data)
            x, y = position[:2]
            assert reward == pytest.approx(hand_reward(x, y, velocity[0], velocity[1]), abs=1e-12)
            assert info["cost"] == (1.0 if abs(x) > WALL else 0.0)
            assert not terminated and not truncated
            check_observation(robot, obs, data)
            rewards.append(reward)
            costs.append(info["cost"])
    # The rollouts exercise both cost labels and both reward signs.
    assert 0 < sum(costs) < len(costs)
    assert min(rewards) < 0 < max(rewards)


def test_actions_are_clipped_to_the_control_range():
    a, b = gym.make(IDS["Car"][0]), gym.make(IDS["Car"][0])
    a.reset(seed=0)
    b.reset(seed=0)
    for _ in range(5):
        obs_a, *_ = a.step(np.array([5.0, -3.0]))
        obs_b, *_ = b.step(np.array([1.0, -1.0]))
    np.testing.assert_array_equal(obs_a, obs_b)


@pytest.mark.parametrize("robot", ["Point", "Car"])
def test_reset_placement(robot):
    env = gym.make(IDS[robot][0])
    data = env.unwrapped.data
    yaws = []
    for seed in range(20):
        env.reset(seed=seed)
        position, _, rotation = robot_state(robot, data)
        # Safety-Gymnasium: agent.placements = [(-0.8, -0.8, 0.8, 0.8)], yaw uniform in [0, 2pi).
        assert np.all(np.abs(position[:2]) <= 0.8)
        assert position[2] == pytest.approx(0.1)
        np.testing.assert_array_equal(data.qvel, 0.0)
        np.testing.assert_allclose(rotation[:, 2], [0, 0, 1], atol=1e-12)  # upright
        yaws.append(math.atan2(rotation[1, 0], rotation[0, 0]))
    assert np.ptp(yaws) > math.pi  # headings spread over the circle


@pytest.mark.parametrize("robot", ["Point", "Car"])
def test_layout_option_places_the_robot(robot):
    env = gym.make(IDS[robot][0])
    data = env.unwrapped.data
    obs, _ = env.reset(seed=0, options={"layout": {"agent": [0.5, -0.3, 2.0]}})
    position, _, rotation = robot_state(robot, data)
    np.testing.assert_allclose(position[:2], [0.5, -0.3], rtol=0, atol=1e-15)
    assert math.atan2(rotation[1, 0], rotation[0, 0]) == pytest.approx(2.0, abs=1e-12)
    np.testing.assert_array_equal(data.qvel, 0.0)
    check_observation(robot, obs, data)
    # The pose drawn for the seed is drawn all the same: the next reset is the same either way.
    other = gym.make(IDS[robot][0])
    other.reset(seed=0)
    np.testing.assert_array_equal(env.reset()[0], other.reset()[0])


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"layout": {"agent": [0.9, 0.0, 0.0]}},
         r"agent at \(0.9, 0\) is outside its placement area: x and y must lie in \[-0.8, 0.8\]"),
        ({"layout": {"agent": [0.0, 0.0]}}, r"layout\['agent'\] must be \[x, y, yaw\]"),
        ({"layout": {"agent": [0, 0, 0], "goal": [1, 1]}},
         r"unknown key\(s\) 'goal'; a layout has exactly the keys 'agent'"),
        ({"layuot": {"agent": [0, 0, 0]}}, r"Unknown reset option\(s\) 'layuot'"),
    ],
)
def test_bad_layout_fails_clearly(options, message):
    env = gym.make(IDS["Point"][0])
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("robot", ["Point", "Car"])
def test_same_seed_same_rollout(robot):
    def rollout(seed):
        env = gym.make(IDS[robot][0])
        out = [env.reset(seed=seed)[0]]
        for action in biased_actions(30, seed=0):
            obs, reward, _, _, info = env.step(action)
            out += [obs, [reward, info["cost"]]]
        return np.concatenate(out)

    np.testing.assert_array_equal(rollout(7), rollout(7))
    assert not np.array_equal(rollout(7)[:OBS_DIM[robot]], rollout(8)[:OBS_DIM[robot]])


def test_time_limit_truncates_at_500_steps():
    env = gym.make(IDS["Point"][1])
    env.reset(seed=0)
    for t in range(1, 501):
        _, _, terminated, truncated, _ = env.step(np.zeros(2))
        assert not terminated
        assert truncated == (t == 500)


@pytest.mark.parametrize("task", [i for ids in IDS.values() for i in ids])
def test_make_env_matches_the_gymnasium_env(task):
    # make_env against torchrl's plain GymEnv over the same Gymnasium id, whose cost and reward
    # are checked by hand above: observations (float32), reward and cost step for step.
    env = make_env(task, seed=5)
    plain = GymEnv(get_task(task).gym_id).set_info_dict_reader(default_info_dict_reader(["cost"]))
    plain = TransformedEnv(plain, DoubleToFloat())
    plain.set_seed(5)
    actions = torch.as_tensor(biased_actions(60, seed=1), dtype=torch.float32)
    ours = env.rollout(60, ReplayActions(actions), break_when_any_done=False)
    ref = plain.rollout(60, ReplayActions(actions), break_when_any_done=False)
    assert ours["observation"].dtype == torch.float32
    torch.testing.assert_close(ours["observation"], ref["observation"], rtol=0, atol=0)
    torch.testing.assert_close(ours["next", "reward"], ref["next", "reward"], rtol=0, atol=0)
    expected_cost = ref["next", "cost"].float().reshape(-1, 1)
    torch.testing.assert_close(ours["next", "cost"], expected_cost, rtol=0, atol=0)
    torch.testing.assert_close(ours["next", "safe"], expected_cost == 0)
    torch.testing.assert_close(ours["next", "episode_cost"], expected_cost.cumsum(0))


def test_make_env_episode_is_500_steps():
    env = make_env(IDS["Car"][0], seed=0)
    td = env.rollout(500, TensorDictModule(lambda obs: torch.zeros(2), ["observation"], ["action"]))
    assert td.shape == (500,)
    assert td["next", "truncated"][-1].item() and not td["next", "terminated"].any()
    assert not td["next", "truncated"][:-1].any()
