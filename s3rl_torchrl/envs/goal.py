"""Safety-Gymnasium's Goal level-1 task for the Point robot (``SafetyPointGoal1``), on MuJoCo +
Gymnasium 1.x.

``safety-gymnasium`` 1.0 pins gymnasium 0.28 and mujoco 2.3.3 and does not import on Python 3.11,
so, as for the Circle tasks (``circle.py``), the task is rebuilt here: the Circle tasks' Point
robot (``assets/circle_point.xml``, its floor, frame skip, sensors and pseudo-lidar) in a world
that holds what Safety-Gymnasium's world builder adds for GoalLevel1: a goal, 8 hazards and 1 vase.
Every number below names the Safety-Gymnasium 1.0 file it comes from (paths in
``safety_gymnasium/``); ``docs/tasks.md`` ("Safety-Gymnasium Goal task") writes the rules out.

The layout is drawn exactly as Safety-Gymnasium draws it, from a NumPy ``RandomState`` seeded
with the reset's seed, so ``reset(seed=s)`` places every object where Safety-Gymnasium's
``reset(seed=s)`` does (tested against recorded data). ``reset(options={"layout": ...})`` places
them at given positions instead (:func:`parse_goal_layout`). Dynamics are those of the installed
MuJoCo: trajectories follow Safety-Gymnasium's (mujoco 2.3.3) step for step only until the two
MuJoCo versions part (``docs/tasks.md``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
import torch
from gymnasium.envs.mujoco import MujocoEnv
from gymnasium.utils import EzPickle

from s3rl_torchrl.envs.circle import (
    ASSETS,
    FRAME_SKIP,
    LIDAR_NUM_BINS,
    REWARD_CLIP,
    SITE_SENSORS,
    pseudo_lidars,
)
from s3rl_torchrl.envs.layout import (
    Placed,
    as_list,
    as_vector,
    check_in_area,
    check_keepouts,
    check_keys,
    layout_from_options,
)
from s3rl_torchrl.envs.spec import TaskSpec
from s3rl_torchrl.envs.state import generator_state, set_generator_state

# bases/base_task.py: BaseTask.num_steps = 1000; safety_gymnasium/__init__.py registers every Goal
# id with max_episode_steps=1000.
GOAL_MAX_EPISODE_STEPS = 1000
# The paper's Table 3 cost limit, which it uses for every task (Table 1 reports episode costs of
# ~94-103 on this task for both algorithms, far above it).
GOAL_COST_LIMIT = 10.0

# -- placement: where reset puts things ----------------------------------------------------
# goal_level1.py: placements_conf.extents = [-1.5, -1.5, 1.5, 1.5] (min x, min y, max x, max y).
PLACEMENT_EXTENTS = (-1.5, -1.5, 1.5, 1.5)
# bases/underlying.py: PlacementsConf.margin (added to every pair of keep-outs).
PLACEMENT_MARGIN = 0.0
# agents/point.py, bases/base_agent.py: keepout=0.4.
AGENT_KEEPOUT = 0.4
# goal_level0.py: Goal(keepout=0.305) (assets/geoms/goal.py's default 0.4 is overridden).
GOAL_KEEPOUT = 0.305
# goal_level1.py: Hazards(num=8, keepout=0.18); Vases(num=1, is_constrained=False);
# assets/free_geoms/vases.py: Vases.keepout = 0.15.
NUM_HAZARDS = 8
HAZARD_KEEPOUT = 0.18
NUM_VASES = 1
VASE_KEEPOUT = 0.15
# utils/random_generator.py: build_layout (10000 layouts), sample_layout (100 draws per object);
# bases/base_task.py: build_goal_position (10000 goal draws).
LAYOUT_TRIES, OBJECT_TRIES, GOAL_TRIES = 10_000, 100, 10_000

# -- objects ----------------------------------------------------------------------------------
# assets/geoms/goal.py: Goal.size = 0.3 (the goal is reached at distance <= size), a cylinder of
# height size/2 centred at z = size/2 + 1e-2, never colliding (contype = conaffinity = 0).
GOAL_SIZE = 0.3
GOAL_Z = GOAL_SIZE / 2 + 1e-2
# assets/geoms/goal.py: reward_distance = 1.0 (per metre of progress), reward_goal = 1.0.
REWARD_DISTANCE = 1.0
REWARD_GOAL = 1.0
# assets/geoms/hazards.py: Hazards.size = 0.2, cost = 1.0, a flat cylinder (half-height 1e-2) at
# z = 2e-2 that never collides.
HAZARD_SIZE = 0.2
HAZARD_COST = 1.0
HAZARD_Z = 2e-2
# assets/free_geoms/vases.py: a free box of half-size 0.1, density 0.001, that sinks 4e-5 into
# the floor (its centre starts at z = size - sink); it collides with the robot and the floor.
VASE_SIZE = 0.1
VASE_DENSITY = 0.001
VASE_Z = VASE_SIZE - 4e-5
# assets/xmls/point.xml: the agent body's height (Safety-Gymnasium's agent.z_height).
AGENT_Z = 0.1

# -- observation --------------------------------------------------------------------------------
# bases/base_task.py: LidarConf() defaults, which GoalLevel0/1 keep: 16 bins, pseudo, aliased,
# max_dist = 3 (linear closeness max(0, 3 - d) / 3; exp_gain = 1.0 only applies when max_dist is
# None).
LIDAR_MAX_DIST = 3.0
# bases/base_task.py: build_observation_space/obs: the sensors (bases/base_agent.py:
# SensorConf.sensors), then one lidar per lidar-observed object in the task's order: goal,
# hazards, vases (assets/geoms/*.py, assets/free_geoms/vases.py: is_lidar_observed = True).
LIDAR_OBJECTS = ("goal", "hazards", "vases")
# bases/underlying.py: SimulationConf(frameskip_binom_n=10, frameskip_binom_p=1.0): the number of
# physics steps is drawn as binomial(10, 1.0) = 10 from the layout generator every env step.
FRAME_SKIP_P = 1.0

# Colours (assets/color.py): rendering only. Safety-Gymnasium's geom groups (assets/group.py,
# for its ray-cast lidar) are left at 0, so that Gymnasium's renderer, which draws groups 0-2,
# shows every object.
_RGBA = {"goal": (0, 1, 0, 0.25), "hazard": (0, 0, 1, 0.25), "vase": (0, 1, 1, 1)}


def _yaw_quat(yaw: float) -> np.ndarray:
    """The unit quaternion of a rotation by ``yaw`` about z (utils/common_utils.py: rot2quat),
    divided by its norm. That gives, bit for bit, the quaternions mujoco 2.3.3 compiled from
    Safety-Gymnasium's world XML for the recorded layouts (tests/envs/test_goal.py);
    ``mju_normalize4``, which leaves a norm within 1e-15 of 1 alone, was one bit off for one."""
    w, z = math.cos(yaw / 2), math.sin(yaw / 2)
    norm = math.sqrt(w * w + z * z)
    return np.array([w / norm, 0.0, 0.0, z / norm])


@dataclass(frozen=True)
class GoalLayout:
    """Where a Goal episode starts: agent ``(x, y, yaw)``, goal ``(x, y)``, hazards ``(8, 2)``,
    vases ``(1, 3)`` as ``(x, y, yaw)``."""

    agent: np.ndarray
    goal: np.ndarray
    hazards: np.ndarray
    vases: np.ndarray

    def as_option(self) -> dict[str, Any]:
        """The layout as ``reset(options={"layout": ...})`` takes it (plain lists)."""
        return {
            "agent": self.agent.tolist(),
            "goal": self.goal.tolist(),
            "hazards": self.hazards.tolist(),
            "vases": self.vases.tolist(),
        }


LAYOUT_KEYS = ("agent", "goal", "hazards", "vases")


def _area(keepout: float) -> tuple[float, float]:
    """An object's placement area: the extents shrunk by its keep-out, computed as
    utils/random_generator.py: constrain_placement does (the extents are square)."""
    xmin, _, xmax, _ = PLACEMENT_EXTENTS
    return xmin + keepout, xmax - keepout


def parse_goal_layout(layout: Mapping[str, Any]) -> GoalLayout:
    """Check a layout for ``reset(options={"layout": layout})`` and return it as arrays.

    ``layout`` has exactly the keys ``agent`` (``[x, y, yaw]``), ``goal`` (``[x, y]``),
    ``hazards`` (8 ``[x, y]``) and ``vases`` (1 ``[x, y]`` or ``[x, y, yaw]``; yaw 0 if left
    out). Like Safety-Gymnasium's own layouts: every object lies in its placement area (the
    extents ``[-1.5, 1.5]`` shrunk by its keep-out radius) and no two objects are closer than
    the sum of their keep-out radii (agent 0.4, goal 0.305, hazard 0.18, vase 0.15). Raises a
    ``ValueError`` naming the first problem.
    """
    check_keys(layout, LAYOUT_KEYS)
    agent = as_vector(layout["agent"], "layout['agent']", (3,), "[x, y, yaw]")
    goal = as_vector(layout["goal"], "layout['goal']", (2,), "[x, y]")
    hazards = np.array([
        as_vector(h, f"layout['hazards'][{i}]", (2,), "[x, y]")
        for i, h in enumerate(as_list(layout["hazards"], "layout['hazards']", NUM_HAZARDS,
                                      "[x, y] positions"))
    ])
    vases = np.array([
        np.r_[v, 0.0] if len(v) == 2 else v
        for v in (
            as_vector(v, f"layout['vases'][{i}]", (2, 3), "[x, y] or [x, y, yaw]")
            for i, v in enumerate(as_list(layout["vases"], "layout['vases']", NUM_VASES,
                                          "[x, y] or [x, y, yaw]"))
        )
    ])
    items = [
        Placed("agent", agent[:2], AGENT_KEEPOUT),
        Placed("goal", goal, GOAL_KEEPOUT),
        *(Placed(f"hazards[{i}]", h, HAZARD_KEEPOUT) for i, h in enumerate(hazards)),
        *(Placed(f"vases[{i}]", v[:2], VASE_KEEPOUT) for i, v in enumerate(vases)),
    ]
    for item in items:
        low, high = _area(item.keepout)
        check_in_area(item, low, high, f"the extents [-1.5, 1.5] shrunk by its keep-out "
                                       f"{item.keepout:g}, goal_level1.py")
    check_keepouts(items, PLACEMENT_MARGIN)
    return GoalLayout(agent, goal, hazards, vases)


def _random_state(seed: int) -> np.random.RandomState:
    """Safety-Gymnasium's generator for a reset seed: ``RandomState(seed)``
    (utils/random_generator.py: set_random_seed). Seeds beyond its 32-bit range, which
    Gymnasium allows, go through a ``SeedSequence`` instead."""
    if 0 <= seed < 2**32:
        return np.random.RandomState(seed)
    return np.random.RandomState(np.random.SeedSequence(seed).generate_state(8))


class LayoutSampler:
    """Safety-Gymnasium's random layout of GoalLevel1, draw for draw.

    ``utils/random_generator.py`` places the agent, then the goal, the 8 hazards and the vase,
    each uniformly in its placement area (the extents shrunk by its keep-out) and redrawn up to
    100 times while it is closer to an already placed object than their two keep-outs; a layout
    that fails is redrawn whole. ``bases/base_task.py: _build_world_config`` then draws the
    agent's yaw and one rotation per object (goal, hazards, vase) in ``[0, 2*pi)``, and
    ``goal_level0.py: update_world`` draws the goal again, away from the other objects.
    """

    def __init__(self, rng: np.random.RandomState):
        self.rng = rng

    def _draw_xy(self, keepout: float) -> np.ndarray:
        # utils/random_generator.py: draw_placement with no placements (the full extents).
        xmin, ymin, xmax, ymax = PLACEMENT_EXTENTS
        xmin, ymin, xmax, ymax = xmin + keepout, ymin + keepout, xmax - keepout, ymax - keepout
        return np.array([self.rng.uniform(xmin, xmax), self.rng.uniform(ymin, ymax)])

    @staticmethod
    def _is_free(xy: np.ndarray, keepout: float, others: list[tuple[np.ndarray, float]]) -> bool:
        for other_xy, other_keepout in others:
            dist = np.sqrt(np.sum(np.square(xy - other_xy)))
            if dist < other_keepout + PLACEMENT_MARGIN + keepout:
                return False
        return True

    def _positions(self) -> list[np.ndarray]:
        keepouts = [AGENT_KEEPOUT, GOAL_KEEPOUT, *[HAZARD_KEEPOUT] * NUM_HAZARDS,
                    *[VASE_KEEPOUT] * NUM_VASES]
        for _ in range(LAYOUT_TRIES):
            placed: list[tuple[np.ndarray, float]] = []
            for keepout in keepouts:
                for _ in range(OBJECT_TRIES):
                    xy = self._draw_xy(keepout)
                    if self._is_free(xy, keepout, placed):
                        placed.append((xy, keepout))
                        break
                else:
                    break
            else:
                return [xy for xy, _ in placed]
        raise RuntimeError("Failed to sample a layout of objects (10000 tries).")

    def new_goal(self, others: list[tuple[np.ndarray, float]]) -> np.ndarray | None:
        """A goal away from ``others`` (positions, keep-outs), or ``None`` after 10000 draws."""
        for _ in range(GOAL_TRIES):
            xy = self._draw_xy(GOAL_KEEPOUT)
            if self._is_free(xy, GOAL_KEEPOUT, others):
                return xy
        return None

    def layout(self) -> GoalLayout:
        agent, _first_goal, *rest = self._positions()
        hazards, vases = rest[:NUM_HAZARDS], rest[NUM_HAZARDS:]
        yaw = self.rng.uniform(0, 2 * np.pi)
        for _ in range(1 + NUM_HAZARDS):  # the goal's and hazards' rotations (symmetric shapes)
            self.rng.uniform(0, 2 * np.pi)
        vase_yaws = [self.rng.uniform(0, 2 * np.pi) for _ in range(NUM_VASES)]
        others = [(agent, AGENT_KEEPOUT), *((h, HAZARD_KEEPOUT) for h in hazards),
                  *((v, VASE_KEEPOUT) for v in vases)]
        goal = self.new_goal(others)
        if goal is None:
            raise RuntimeError("Failed to generate a goal (10000 tries).")
        return GoalLayout(
            agent=np.r_[agent, yaw],
            goal=goal,
            hazards=np.array(hazards),
            vases=np.array([np.r_[v, vy] for v, vy in zip(vases, vase_yaws)]),
        )


def hazard_cost(agent_xy: np.ndarray, hazards_xy: np.ndarray) -> float:
    """Level 1's cost: 1.0 when the robot body is inside a hazard, else 0.0.

    ``assets/geoms/hazards.py: cal_cost`` sums ``1.0 * (0.2 - d)`` over the hazards at planar
    distance ``d <= 0.2`` from the robot body; ``builder.py: _cost`` turns that into the
    indicator ``sum > 0`` (``CostConf.constrain_indicator``), so a hazard counts when ``d < 0.2``.
    """
    dist = np.sqrt(np.sum(np.square(hazards_xy - agent_xy), axis=1))
    inside = dist <= HAZARD_SIZE
    return float(np.sum(HAZARD_COST * (HAZARD_SIZE - dist[inside])) > 0.0)


def hazard_margin(agent_xy: np.ndarray, hazards_xy: np.ndarray) -> float:
    """The graded form of :func:`hazard_cost`: planar distance from the robot body to the
    nearest hazard's edge, ``min_i d_i - 0.2`` (metres).

    Negative inside a hazard, so the cost is 1 exactly when the margin is negative. A
    training-only label (``info["cost_margin"]``), never an observation (the robot sees the
    hazards only through its lidar).
    """
    dist = np.sqrt(np.sum(np.square(hazards_xy - agent_xy), axis=1))
    return float(dist.min() - HAZARD_SIZE)


def goal_lidars(agent_pos: np.ndarray, agent_mat: np.ndarray,
                objects: dict[str, np.ndarray]) -> np.ndarray:
    """The goal, hazards and vases lidars (16 bins each, concatenated) seen by the robot.

    ``objects`` maps each of :data:`LIDAR_OBJECTS` to its objects' planar positions ``(n, 2)``.
    Each position, at height 0, is taken into the robot's frame (``bases/base_task.py:
    _ego_xy``: ``([x, y, 0] - agent_pos) @ agent_mat``, first two components) and read by the
    pseudo-lidar with ``max_dist`` 3.
    """
    xy = np.concatenate([objects[name] for name in LIDAR_OBJECTS])
    groups = np.repeat(np.arange(len(LIDAR_OBJECTS)), [len(objects[n]) for n in LIDAR_OBJECTS])
    dx, dy, dz = xy[:, 0] - agent_pos[0], xy[:, 1] - agent_pos[1], 0.0 - agent_pos[2]
    # The vector-matrix product written out: the same sums, in the same order, as NumPy's
    # product of one (3,) vector by the (3, 3) matrix in Safety-Gymnasium, so the readings are
    # bit for bit its own (a batched (n, 3) @ (3, 3) product rounds differently).
    ego = np.column_stack([
        0.0 + dx * agent_mat[0, 0] + dy * agent_mat[1, 0] + dz * agent_mat[2, 0],
        0.0 + dx * agent_mat[0, 1] + dy * agent_mat[1, 1] + dz * agent_mat[2, 1],
    ])
    return pseudo_lidars(ego, groups, len(LIDAR_OBJECTS), LIDAR_NUM_BINS, LIDAR_MAX_DIST)


def build_goal_world(spec: mujoco.MjSpec) -> None:
    """Turn the Circle tasks' Point world into GoalLevel1's: drop the circle and its walls, add
    the vase, the goal and the hazards (in Safety-Gymnasium's body order: free geoms, then geoms;
    ``world.py: build``). Positions are placeholders; every reset sets them."""
    for name in ("circle", "sigwall_pos_x", "sigwall_neg_x"):
        spec.delete(spec.geom(name))
    for i in range(NUM_VASES):
        body = spec.worldbody.add_body(name=f"vase{i}", pos=[0.0, 0.0, VASE_Z])
        body.add_freejoint(name=f"vase{i}")
        body.add_geom(name=f"vase{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=[VASE_SIZE] * 3,
                      density=VASE_DENSITY, rgba=_RGBA["vase"])
    body = spec.worldbody.add_body(name="goal", pos=[0.0, 0.0, GOAL_Z])
    body.add_geom(name="goal", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  size=[GOAL_SIZE, GOAL_SIZE / 2, 0.0], contype=0, conaffinity=0,
                  rgba=_RGBA["goal"])
    for i in range(NUM_HAZARDS):
        body = spec.worldbody.add_body(name=f"hazard{i}", pos=[0.0, 0.0, HAZARD_Z])
        body.add_geom(name=f"hazard{i}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                      size=[HAZARD_SIZE, 1e-2, 0.0], contype=0, conaffinity=0,
                      rgba=_RGBA["hazard"])


class PointGoalEnv(MujocoEnv, EzPickle):
    """``SafetyPointGoal1``: drive the Point robot to a goal, again and again, avoiding hazards.

    Each step clips the action to the actuators' control range, runs 10 physics steps and
    ``mj_forward``, then: reward = decrease of the planar distance to the goal (x1.0), plus 1.0
    when the robot is within 0.3 of the goal, after which a new goal is drawn away from the
    other objects (the episode terminates only if none can be drawn); cost
    (:func:`hazard_cost`) in ``info["cost"]`` and ``info["cost_hazards"]``; ``info["goal_met"]``.
    The episode is truncated at 1000 steps by the registered time limit.

    Observation (float64, 60): accelerometer, velocimeter, gyro, magnetometer (3 each, robot
    frame), then the goal, hazards and vases lidars (16 bins each, :func:`goal_lidars`).

    ``reset(seed=s)`` draws the layout as Safety-Gymnasium does for seed ``s``
    (:class:`LayoutSampler`); ``reset(options={"layout": {...}})`` places the objects there
    instead (checked by :func:`parse_goal_layout` before the physics is touched). The layout is
    drawn all the same, so the generator's stream (later goals, later resets) does not depend on
    whether a layout was given. :attr:`start_layout` is the layout of the current episode.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["human", "rgb_array", "depth_array"],
        "render_fps": 50,
    }

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
            str(ASSETS / "circle_point.xml"),
            FRAME_SKIP,
            observation_space=None,
            render_mode=render_mode,
            width=width,
            height=height,
            camera_name=camera_name,
            camera_id=camera_id,
            # Top-down view of the whole arena (extents +-1.5).
            default_camera_config={"distance": 5.5, "elevation": -90.0, "lookat": [0, 0, 0]},
        )
        model = self.model
        self._agent_id = model.body("agent").id
        self._goal_id = model.body("goal").id
        self._hazard_ids = [model.body(f"hazard{i}").id for i in range(NUM_HAZARDS)]
        self._vase_ids = [model.body(f"vase{i}").id for i in range(NUM_VASES)]
        self._vase_qpos = [int(model.jnt_qposadr[model.body(f"vase{i}").jntadr[0]])
                           for i in range(NUM_VASES)]
        self._sensors = [slice(int(model.sensor(s).adr[0]),
                               int(model.sensor(s).adr[0] + model.sensor(s).dim[0]))
                         for s in SITE_SENSORS]
        n_sensors = sum(s.stop - s.start for s in self._sensors)
        n_lidar = LIDAR_NUM_BINS * len(LIDAR_OBJECTS)
        self.observation_space = gym.spaces.Box(
            low=np.concatenate([np.full(n_sensors, -np.inf), np.zeros(n_lidar)]),
            high=np.concatenate([np.full(n_sensors, np.inf), np.ones(n_lidar)]),
            dtype=np.float64,
        )
        self._rng: np.random.RandomState | None = None
        self._layout: GoalLayout | None = None  # a pending reset's layout option
        self._start_layout: GoalLayout | None = None
        self._last_dist_goal = 0.0

    def _initialize_simulation(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        spec = mujoco.MjSpec.from_file(self.fullpath)
        build_goal_world(spec)
        model = spec.compile()
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, self.height)
        return model, mujoco.MjData(model)

    # -- state read by the task ---------------------------------------------------------------
    @property
    def start_layout(self) -> dict[str, Any]:
        """The layout the current episode started from, as ``reset(options={"layout": ...})``
        takes it (a seeded reset's layout, replayable exactly)."""
        if self._start_layout is None:
            raise RuntimeError("Call reset() first.")
        return self._start_layout.as_option()

    def _agent_xy(self) -> np.ndarray:
        return self.data.xpos[self._agent_id, :2]

    def _goal_xy(self) -> np.ndarray:
        return self.data.xpos[self._goal_id, :2]

    def _dist_goal(self) -> float:
        # bases/base_agent.py: dist_xy, planar distance between the body frames.
        return float(np.sqrt(np.sum(np.square(self._goal_xy() - self._agent_xy()))))

    def _hazards_xy(self) -> np.ndarray:
        return self.data.xpos[self._hazard_ids, :2]

    def _vases_xy(self) -> np.ndarray:
        return self.data.xpos[self._vase_ids, :2]

    def _get_obs(self) -> np.ndarray:
        sensordata = self.data.sensordata
        lidars = goal_lidars(
            self.data.xpos[self._agent_id],
            self.data.xmat[self._agent_id].reshape(3, 3),
            {"goal": self._goal_xy()[None], "hazards": self._hazards_xy(),
             "vases": self._vases_xy()},
        )
        return np.concatenate([*(sensordata[s] for s in self._sensors), lidars])

    # -- exact snapshots (envs/state.py) ------------------------------------------------------
    def snapshot_extra(self) -> dict[str, Any]:
        """What the next steps read besides MjData and ``np_random``: the model fields a layout
        and a new goal move, the layout generator, the last goal distance, the start layout."""
        model = self.model
        start = self._start_layout
        return {
            "body_pos": torch.from_numpy(model.body_pos.copy()),
            "body_quat": torch.from_numpy(model.body_quat.copy()),
            "qpos0": torch.from_numpy(model.qpos0.copy()),
            "rng": None if self._rng is None else generator_state(self._rng),
            "last_dist_goal": float(self._last_dist_goal),
            "start_layout": None
            if start is None
            else [
                torch.from_numpy(np.asarray(getattr(start, name), dtype=np.float64))
                for name in ("agent", "goal", "hazards", "vases")
            ],
        }

    def restore_extra(self, state: dict[str, Any]) -> None:
        model = self.model
        model.body_pos[:] = state["body_pos"].numpy()
        model.body_quat[:] = state["body_quat"].numpy()
        model.qpos0[:] = state["qpos0"].numpy()
        # The constants the compiler derives from the initial pose, as _apply_layout does; the
        # data it uses as scratch is overwritten by the snapshot's MjData afterwards.
        mujoco.mj_setConst(model, self.data)
        if state["rng"] is None:
            self._rng = None
        else:
            self._rng = np.random.RandomState()
            set_generator_state(self._rng, state["rng"])
        self._last_dist_goal = state["last_dist_goal"]
        start = state["start_layout"]
        self._start_layout = None if start is None else GoalLayout(*(t.numpy() for t in start))
        self._layout = None

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        layout = layout_from_options(options)
        # Checked before the physics (or the generator) is touched.
        self._layout = None if layout is None else parse_goal_layout(layout)
        if seed is not None:
            self._rng = _random_state(seed)
        elif self._rng is None:
            # Never seeded: Safety-Gymnasium then seeds from NumPy's global generator
            # (builder.py: set_seed); here from the env's own np_random.
            self._rng = np.random.RandomState(int(self.np_random.integers(2**32)))
        return super().reset(seed=seed)

    def reset_model(self) -> np.ndarray:
        assert self._rng is not None
        drawn = LayoutSampler(self._rng).layout()
        layout = self._layout if self._layout is not None else drawn
        self._layout = None
        self._apply_layout(layout)
        return self._get_obs()

    def _apply_layout(self, layout: GoalLayout) -> None:
        model = self.model
        x, y, yaw = layout.agent
        # As Safety-Gymnasium's world builder: the agent's body frame is put at the pose (its
        # slide joints then move along the rotated axes) and every joint starts at 0.
        model.body_pos[self._agent_id] = (x, y, AGENT_Z)
        model.body_quat[self._agent_id] = _yaw_quat(yaw)
        model.body_pos[self._goal_id, :2] = layout.goal
        model.body_pos[self._hazard_ids, :2] = layout.hazards
        qpos = np.zeros(model.nq)
        for body, adr, (vx, vy, vyaw) in zip(self._vase_ids, self._vase_qpos, layout.vases):
            pose = (vx, vy, VASE_Z, *_yaw_quat(vyaw))
            qpos[adr : adr + 7] = pose
            # The free body's model pose too (its reference pose), as in Safety-Gymnasium's XML.
            model.body_pos[body], model.body_quat[body] = pose[:3], pose[3:]
        # Safety-Gymnasium compiles a new model for every layout, and the compiler derives some
        # constants from the initial pose (e.g. the inverse weights that scale the contacts'
        # softness); recomputed here for this pose, as the compiler would.
        model.qpos0[:] = qpos
        mujoco.mj_setConst(model, self.data)
        self.set_state(qpos, np.zeros(model.nv))  # set_state runs mj_forward
        self._start_layout = GoalLayout(*(np.array(a, dtype=np.float64) for a in (
            layout.agent, layout.goal, layout.hazards, layout.vases)))
        self._last_dist_goal = self._dist_goal()

    def _new_goal(self) -> bool:
        """Draw a new goal away from the objects where they are now (``builder.py: step``:
        ``update_layout`` then ``update_world``); ``False`` if none could be drawn."""
        assert self._rng is not None
        others = [(self._agent_xy().copy(), AGENT_KEEPOUT),
                  *((h.copy(), HAZARD_KEEPOUT) for h in self._hazards_xy()),
                  *((v.copy(), VASE_KEEPOUT) for v in self._vases_xy())]
        goal = LayoutSampler(self._rng).new_goal(others)
        if goal is None:
            return False
        self.model.body_pos[self._goal_id, :2] = goal
        mujoco.mj_forward(self.model, self.data)
        self._last_dist_goal = self._dist_goal()
        return True

    def step(self, action):
        assert self._rng is not None, "Call reset() first."
        low, high = self.model.actuator_ctrlrange.T
        self.data.ctrl[:] = np.clip(action, low, high)
        # Drawn (always 10) to keep the generator's stream Safety-Gymnasium's.
        n_steps = self._rng.binomial(FRAME_SKIP, FRAME_SKIP_P)
        mujoco.mj_step(self.model, self.data, nstep=int(n_steps))
        mujoco.mj_forward(self.model, self.data)  # sensors of the new state

        # goal_level0.py: calculate_reward; builder.py: _reward (the clip).
        dist = self._dist_goal()
        reward = (self._last_dist_goal - dist) * REWARD_DISTANCE
        self._last_dist_goal = dist
        goal_met = dist <= GOAL_SIZE
        if goal_met:
            reward += REWARD_GOAL
        reward = float(np.clip(reward, -REWARD_CLIP, REWARD_CLIP))
        cost = hazard_cost(self._agent_xy(), self._hazards_xy())
        # numpy scalars (float subclasses): torchrl's info reader needs a dtype.
        info = {"cost": np.float64(cost), "cost_hazards": np.float64(cost),
                "cost_margin": np.float64(hazard_margin(self._agent_xy(), self._hazards_xy())),
                "goal_met": bool(goal_met)}
        terminated = False
        if goal_met:
            # builder.py: a new goal (continue_goal); if none fits, the episode ends
            # (terminate_resample_failure).
            terminated = not self._new_goal()
        if self.render_mode == "human":
            self.render()
        return self._get_obs(), reward, terminated, False, info


_SOURCE = "Safety-Gymnasium 1.0 Goal level 1 (native rebuild on MuJoCo)"
_COST_RULE = f"1 if the robot is inside one of the {NUM_HAZARDS} hazards (distance < {HAZARD_SIZE})"
_MARGIN_RULE = f"distance to the nearest hazard minus {HAZARD_SIZE} (m)"

#: The registry entries: Safety-Gymnasium's id and the paper's Gymnasium-API id (same task).
GOAL_TASKS: tuple[TaskSpec, ...] = tuple(
    TaskSpec(
        env_id=name,
        family="goal",
        source=_SOURCE,
        max_episode_steps=GOAL_MAX_EPISODE_STEPS,
        cost_limit=GOAL_COST_LIMIT,
        obs_dim=12 + LIDAR_NUM_BINS * len(LIDAR_OBJECTS),
        act_dim=2,
        cost_rule=_COST_RULE,
        margin_rule=_MARGIN_RULE,
        alias_of=alias_of,
    )
    for name, alias_of in (
        ("SafetyPointGoal1-v0", None),
        ("SafetyPointGoal1Gymnasium-v0", "SafetyPointGoal1-v0"),
    )
)


def register_goal_tasks() -> None:
    """Register the Goal ids with Gymnasium (idempotent; runs on import of the package)."""
    for spec in GOAL_TASKS:
        if spec.env_id not in gym.registry:
            gym.register(id=spec.env_id, entry_point=PointGoalEnv,
                         max_episode_steps=spec.max_episode_steps)
