"""Safety-Gymnasium's Circle tasks (level 1) for the Point and Car robots, on MuJoCo + Gymnasium 1.x.

``safety-gymnasium`` 1.0 pins gymnasium 0.28 and mujoco 2.3.3 and does not import on Python 3.11,
so, as for the velocity tasks, the tasks are rebuilt here: the robots are our own MJCF files
(``assets/circle_point.xml``, ``assets/circle_car.xml``) with Safety-Gymnasium's degrees of
freedom, masses, actuators and sensors, and the task's rules are its Circle task's. Every number
below names the Safety-Gymnasium 1.0 file it comes from; ``docs/tasks.md`` ("Safety-Gymnasium
Circle tasks") writes the formulas out. Dynamics are those of the installed MuJoCo, so they are
close to but not bit-identical with Safety-Gymnasium's (mujoco 2.3.3).
"""

from __future__ import annotations

import math
from importlib.resources import files
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.envs.mujoco import MujocoEnv
from gymnasium.utils import EzPickle

from s3rl_torchrl.envs.layout import (
    Placed,
    as_vector,
    check_in_area,
    check_keys,
    layout_from_options,
)
from s3rl_torchrl.envs.spec import TaskSpec

# tasks/safe_navigation/circle/circle_level0.py: num_steps = 500 (also the registered
# max_episode_steps of every Circle id in safety_gymnasium/__init__.py).
CIRCLE_MAX_EPISODE_STEPS = 500
# assets/geoms/circle.py: Circle.radius.
CIRCLE_RADIUS = 1.5
# circle_level0.py: reward_factor.
REWARD_FACTOR = 0.1
# bases/base_task.py: RewardConf.reward_clip (a last resort against physics blow-ups).
REWARD_CLIP = 10.0
# circle_level1.py: Sigwalls(num=2, locate_factor=1.125, is_constrained=True); the cost rule is
# assets/geoms/sigwalls.py: Sigwalls.cal_cost, |x| > locate_factor (x only when num == 2).
WALL_X = 1.125
# bases/base_task.py: LidarConf (num_bins=16, type='pseudo', alias=True); circle_level0.py sets
# lidar_conf.max_dist = 6. The circle geom (at the origin) is the only lidar-observed object.
LIDAR_NUM_BINS = 16
LIDAR_MAX_DIST = 6.0
# circle_level0.py: agent.placements = [(-0.8, -0.8, 0.8, 0.8)], keepout 0; the yaw is
# RandomGenerator.random_rot(), uniform in [0, 2*pi) (utils/random_generator.py).
PLACEMENT_HALF_WIDTH = 0.8
# bases/underlying.py: SimulationConf(frameskip_binom_n=10, frameskip_binom_p=1.0): always
# 10 physics steps per env step.
FRAME_SKIP = 10
# The paper's Table 3 default cost limit, for every task.
CIRCLE_COST_LIMIT = 10.0

# bases/base_agent.py: SensorConf.sensors, read in this order, then the ball joints' angular
# velocities, then their quaternions as 3x3 rotation matrices (row-major); the task appends
# the circle lidar (bases/base_task.py: build_observation_space/obs, flattened in that order).
SITE_SENSORS: tuple[str, ...] = ("accelerometer", "velocimeter", "gyro", "magnetometer")

ASSETS = files("s3rl_torchrl.envs") / "assets"


def circle_reward(x: float, y: float, vx: float, vy: float) -> float:
    """Safety-Gymnasium's Circle reward from the robot body's planar position and velocity.

    ``0.1 * ((-vx*y + vy*x) / r) / (1 + |r - 1.5|)`` with ``r = sqrt(x^2 + y^2)``: the speed
    along the counter-clockwise tangent of the circle through the robot, damped by the distance
    to the circle of radius 1.5 (``circle_level0.py: calculate_reward``), then clipped to
    ``[-10, 10]`` like every Safety-Gymnasium reward (``builder.py: _reward``).
    """
    radius = math.hypot(x, y)
    reward = ((-vx * y + vy * x) / radius) / (1.0 + abs(radius - CIRCLE_RADIUS)) * REWARD_FACTOR
    return float(np.clip(reward, -REWARD_CLIP, REWARD_CLIP))


def boundary_cost(x: float) -> float:
    """Level 1's cost: 1.0 when the robot body is beyond a wall, ``|x| > 1.125``, else 0.0."""
    return float(abs(x) > WALL_X)


def pseudo_lidar(
    ego_xy: np.ndarray, num_bins: int = LIDAR_NUM_BINS, max_dist: float = LIDAR_MAX_DIST
) -> np.ndarray:
    """Safety-Gymnasium's aliased pseudo-lidar of points given in the robot's frame.

    ``ego_xy``: one point ``(x, y)`` or an ``(n, 2)`` array of points. Each point's bearing
    ``angle in [0, 2*pi)`` falls in bin ``k = floor(angle / (2*pi/n))``, which reads
    ``s = max(0, max_dist - dist) / max_dist``; the two neighbours read ``alias * s`` (bin k+1)
    and ``(1 - alias) * s`` (bin k-1), ``alias`` being the bearing's fraction across bin k; with
    several points every bin keeps the largest reading (``bases/base_task.py:
    _obs_lidar_pseudo``); all other bins read 0. ``max_dist`` is 6 for the Circle tasks
    (``circle_level0.py``) and 3 for the Goal task (``LidarConf`` default).
    """
    points = np.asarray(ego_xy, dtype=np.float64).reshape(-1, 2)
    return pseudo_lidars(points, np.zeros(len(points), dtype=np.int64), 1, num_bins, max_dist)


def pseudo_lidars(
    ego_xy: np.ndarray, groups: np.ndarray, num_groups: int, num_bins: int, max_dist: float
) -> np.ndarray:
    """One :func:`pseudo_lidar` per group of points, concatenated (``num_groups * num_bins``):
    point ``i`` (row of ``ego_xy``, shape ``(n, 2)``) is seen by lidar ``groups[i]``. One pass
    for all of a task's lidars, with the same arithmetic as one call per lidar."""
    obs = np.zeros(num_groups * num_bins)
    # Distance and bearing of x + iy as Safety-Gymnasium takes them (np.abs and np.angle of a
    # complex number; np.hypot rounds differently in the last bit).
    z = np.empty(len(ego_xy), dtype=np.complex128)
    z.real, z.imag = ego_xy[:, 0], ego_xy[:, 1]
    dist = np.abs(z)
    angle = np.angle(z) % (2 * np.pi)
    bin_size = 2 * np.pi / num_bins
    # min(): an angle that rounds to exactly 2*pi must not index past the last bin.
    k = np.minimum((angle / bin_size).astype(np.int64), num_bins - 1)
    sensor = np.maximum(0.0, max_dist - dist) / max_dist
    alias = (angle - bin_size * k) / bin_size
    base = groups * num_bins
    np.maximum.at(obs, base + k, sensor)
    np.maximum.at(obs, base + (k + 1) % num_bins, alias * sensor)
    np.maximum.at(obs, base + (k - 1) % num_bins, (1 - alias) * sensor)
    return obs


class CircleEnv(MujocoEnv, EzPickle):
    """Safety-Gymnasium's Circle level-1 task on one robot (see :class:`PointCircleEnv`,
    :class:`CarCircleEnv`).

    Each step clips the action to the actuators' control range, runs :data:`FRAME_SKIP` physics
    steps, recomputes positions and sensors (``mj_forward``), then reads the reward
    (:func:`circle_reward`) and the cost (:func:`boundary_cost`, in ``info["cost"]``) from the
    robot body's position and velocity. The episode never terminates; the registered time limit
    truncates it at 500 steps. Observation (float64): the site sensors, the ball joints' sensors
    (Car), then the 16-bin lidar of the circle's centre.

    ``reset(options={"layout": {"agent": [x, y, yaw]}})`` starts the robot at rest at that pose
    instead of a random one (:func:`parse_circle_layout` checks it first). The random pose is
    drawn all the same, so the generator's stream, and so every later reset, does not depend on
    whether a layout was given.
    """

    xml_file: ClassVar[str]
    #: Ball joints whose (angular velocity, rotation matrix) sensors are observed.
    ball_joints: ClassVar[tuple[str, ...]] = ()

    def __init__(
        self,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera_name: str | None = None,
        camera_id: int | None = None,
    ):
        EzPickle.__init__(self, render_mode, width, height, camera_name, camera_id)
        MujocoEnv.__init__(
            self,
            str(ASSETS / self.xml_file),
            FRAME_SKIP,
            observation_space=None,
            render_mode=render_mode,
            width=width,
            height=height,
            camera_name=camera_name,
            camera_id=camera_id,
            # Top-down view of the whole arena (circle and walls).
            default_camera_config={"distance": 5.0, "elevation": -90.0, "lookat": [0, 0, 0]},
        )
        self._agent_id = self.model.body("agent").id
        self._layout: tuple[float, float, float] | None = None  # a pending reset's layout
        self._jacp = np.zeros((3, self.model.nv))
        n_sensors = sum(int(self.model.sensor(s).dim[0]) for s in SITE_SENSORS)
        n_sensors += 12 * len(self.ball_joints)  # angular velocity (3) + rotation matrix (9)
        self.observation_space = gym.spaces.Box(
            low=np.concatenate([np.full(n_sensors, -np.inf), np.zeros(LIDAR_NUM_BINS)]),
            high=np.concatenate([np.full(n_sensors, np.inf), np.ones(LIDAR_NUM_BINS)]),
            dtype=np.float64,
        )

    # -- robot state read by the task ------------------------------------------------------
    def agent_position(self) -> np.ndarray:
        """World position of the robot body's frame (Safety-Gymnasium's ``agent.pos``)."""
        return self.data.xpos[self._agent_id].copy()

    def agent_velocity(self) -> np.ndarray:
        """World linear velocity of the robot body's frame origin (``agent.vel``: its
        translational Jacobian times ``qvel``)."""
        mujoco.mj_jacBody(self.model, self.data, self._jacp, None, self._agent_id)
        return self._jacp @ self.data.qvel

    def _sensor(self, name: str) -> np.ndarray:
        return self.data.sensor(name).data.copy()

    def _get_obs(self) -> np.ndarray:
        parts = [self._sensor(name) for name in SITE_SENSORS]
        for joint in self.ball_joints:
            parts.append(self._sensor(f"ballangvel_{joint}"))
        for joint in self.ball_joints:
            rotation = np.zeros(9)
            mujoco.mju_quat2Mat(rotation, self._sensor(f"ballquat_{joint}"))
            parts.append(rotation)
        # The circle's centre (0, 0, 0) in the robot's frame, x and y (base_task.py: _ego_xy).
        ego = (np.zeros(3) - self.agent_position()) @ self.data.xmat[self._agent_id].reshape(3, 3)
        parts.append(pseudo_lidar(ego[:2]))
        return np.concatenate(parts)

    # -- Gymnasium API -----------------------------------------------------------------------
    def step(self, action):
        low, high = self.model.actuator_ctrlrange.T
        self.data.ctrl[:] = np.clip(action, low, high)
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        mujoco.mj_forward(self.model, self.data)  # sensors of the new state, as Safety-Gymnasium
        x, y, _ = self.agent_position()
        vx, vy, _ = self.agent_velocity()
        reward = circle_reward(x, y, vx, vy)
        # numpy scalar (a float subclass): torchrl's info reader needs a dtype.
        info = {"cost": np.float64(boundary_cost(x))}
        if self.render_mode == "human":
            self.render()
        return self._get_obs(), reward, False, False, info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        layout = layout_from_options(options)
        # Checked before the physics (or the generator) is touched.
        self._layout = None if layout is None else parse_circle_layout(layout)
        return super().reset(seed=seed)

    def reset_model(self) -> np.ndarray:
        half = PLACEMENT_HALF_WIDTH
        x, y = self.np_random.uniform(-half, half, size=2)
        yaw = self.np_random.uniform(0.0, 2 * np.pi)
        if self._layout is not None:
            x, y, yaw = self._layout
            self._layout = None
        qpos = self.init_qpos.copy()
        self._place(qpos, x, y, yaw)
        self.set_state(qpos, np.zeros(self.model.nv))
        return self._get_obs()

    def _place(self, qpos: np.ndarray, x: float, y: float, yaw: float) -> None:
        raise NotImplementedError


def parse_circle_layout(layout: dict[str, Any]) -> tuple[float, float, float]:
    """Check a Circle layout, ``{"agent": [x, y, yaw]}``, and return ``(x, y, yaw)``.

    The position must lie in Safety-Gymnasium's placement area, ``|x|, |y| <= 0.8``
    (``circle_level0.py: agent.placements``); the yaw is any finite angle in radians.
    """
    check_keys(layout, ("agent",))
    x, y, yaw = as_vector(layout["agent"], "layout['agent']", (3,), "[x, y, yaw]")
    where = "Safety-Gymnasium's agent placements (-0.8, -0.8, 0.8, 0.8), circle_level0.py"
    check_in_area(Placed("agent", np.array([x, y]), 0.0), -PLACEMENT_HALF_WIDTH,
                  PLACEMENT_HALF_WIDTH, where)
    return float(x), float(y), float(yaw)


class PointCircleEnv(CircleEnv):
    """``SafetyPointCircle1``: the Point robot (slides x/y, hinge yaw; push and turn actions).

    Action ``[push, turn]`` in ``[-1, 1]^2``; observation 28 = 12 sensors + 16 lidar bins.
    """

    xml_file = "circle_point.xml"
    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 50}

    def _place(self, qpos, x, y, yaw):
        qpos[:3] = x, y, yaw  # joints x, y (world axes) and z (yaw)


class CarCircleEnv(CircleEnv):
    """``SafetyCarCircle1``: the Car robot (free chassis, two driven wheels, a rear ball).

    Action ``[left wheel, right wheel]`` in ``[-1, 1]^2``; observation 40 = 12 site sensors
    + 3 (rear ball angular velocity) + 9 (rear ball rotation matrix) + 16 lidar bins.
    """

    xml_file = "circle_car.xml"
    ball_joints = ("rear",)
    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 25}

    def _place(self, qpos, x, y, yaw):
        # Free joint: position (the chassis keeps its height 0.1), then the yaw quaternion
        # (utils/common_utils.py: rot2quat).
        qpos[0:2] = x, y
        qpos[3:7] = math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)


CIRCLE_ENV_CLASSES: dict[str, type[CircleEnv]] = {"Point": PointCircleEnv, "Car": CarCircleEnv}
_OBS_DIMS = {"Point": 28, "Car": 40}
_SOURCE = "Safety-Gymnasium 1.0 Circle level 1 (native rebuild on MuJoCo)"
_COST_RULE = f"1 if |x| > {WALL_X} (robot body outside the two walls)"


def _circle_specs() -> tuple[TaskSpec, ...]:
    specs = []
    for robot in CIRCLE_ENV_CLASSES:
        env_id = f"Safety{robot}Circle1-v0"
        for name, alias_of in ((env_id, None), (f"Safety{robot}Circle1Gymnasium-v0", env_id)):
            specs.append(
                TaskSpec(
                    env_id=name,
                    family="circle",
                    source=_SOURCE,
                    max_episode_steps=CIRCLE_MAX_EPISODE_STEPS,
                    cost_limit=CIRCLE_COST_LIMIT,
                    obs_dim=_OBS_DIMS[robot],
                    act_dim=2,
                    cost_rule=_COST_RULE,
                    alias_of=alias_of,
                )
            )
    return tuple(specs)


#: The registry entries: Safety-Gymnasium's ids and the paper's Gymnasium-API ids (same task;
#: here every id returns Gymnasium's 5-tuple with the cost in ``info["cost"]``).
CIRCLE_TASKS: tuple[TaskSpec, ...] = _circle_specs()


def make_circle_gym_env(*, robot: str, **kwargs: Any) -> CircleEnv:
    """Gymnasium entry point of every registered Circle task."""
    return CIRCLE_ENV_CLASSES[robot](**kwargs)


# Gymnasium reads render modes from the entry point's ``metadata`` before building the env.
make_circle_gym_env.metadata = {"render_modes": ["human", "rgb_array", "depth_array"]}


def register_circle_tasks() -> None:
    """Register every Circle id with Gymnasium (idempotent; runs on import of the package)."""
    for spec in CIRCLE_TASKS:
        if spec.env_id in gym.registry:
            continue
        robot = spec.env_id.removeprefix("Safety").split("Circle")[0]
        gym.register(
            id=spec.env_id,
            entry_point=make_circle_gym_env,
            max_episode_steps=spec.max_episode_steps,
            kwargs={"robot": robot},
        )
