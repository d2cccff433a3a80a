"""Gymnasium envs of the Safety-Gymnasium velocity tasks, on Gymnasium's own MuJoCo robots.

Safety-Gymnasium's velocity tasks are thin subclasses of Gymnasium's v4 MuJoCo envs that add a
per-step cost; safety-gymnasium itself pins gymnasium 0.28 and mujoco 2.3, so it cannot share an
environment with Gymnasium 1.x. We rebuild the same subclasses here: reward, termination,
observation and info are the robot's, and ``info["cost"]`` is the speed-limit indicator.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator
from gymnasium.utils import EzPickle

from s3rl_torchrl.envs.registry import MAX_EPISODE_STEPS, VELOCITY_REGISTRATIONS, SpeedKind


def velocity_reading(info: dict[str, Any], speed: SpeedKind) -> float:
    """The speed a velocity task's cost reads: ``speed="x"`` the signed forward velocity (so
    running backwards never costs), ``speed="xy"`` the planar speed of the torso or centre of
    mass."""
    if speed == "x":
        return float(info["x_velocity"])
    if speed == "xy":
        return math.hypot(float(info["x_velocity"]), float(info["y_velocity"]))
    raise ValueError(f"Unknown speed kind {speed!r}; valid kinds are 'x' and 'xy'.")


def velocity_cost(info: dict[str, Any], threshold: float, speed: SpeedKind) -> np.float64:
    """Safety-Gymnasium's velocity cost: 1.0 if the speed (:func:`velocity_reading`) is
    strictly above ``threshold``."""
    return cost_of_margin(velocity_margin(info, threshold, speed))


def velocity_margin(info: dict[str, Any], threshold: float, speed: SpeedKind) -> np.float64:
    """The graded form of :func:`velocity_cost`: ``threshold - speed``, in the speed's units.

    Positive below the limit, zero at it, negative above it: the cost is 1 exactly when the
    margin is negative. A training-only label (``info["cost_margin"]``), never an observation.
    """
    return np.float64(threshold - velocity_reading(info, speed))


def cost_of_margin(margin: float) -> np.float64:
    """1.0 where the margin is negative, i.e. the speed strictly above the threshold (IEEE
    subtraction keeps the sign of ``threshold - speed``: zero only at equality)."""
    # numpy scalar (a float subclass): torchrl's info reader needs a dtype.
    return np.float64(margin < 0)


class VelocityCostMixin:
    """Adds ``info["cost"]`` (and the graded ``info["cost_margin"]``, :func:`velocity_margin`)
    to a Gymnasium MuJoCo env's ``step``; everything else is untouched."""

    def __init__(self, *, cost_threshold: float, cost_speed: SpeedKind, **kwargs: Any):
        super().__init__(**kwargs)
        self.cost_threshold = float(cost_threshold)
        self.cost_speed = cost_speed
        # The robot's own EzPickle args would rebuild it without the cost arguments.
        EzPickle.__init__(self, cost_threshold=cost_threshold, cost_speed=cost_speed, **kwargs)

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        margin = velocity_margin(info, self.cost_threshold, self.cost_speed)
        info["cost"], info["cost_margin"] = cost_of_margin(margin), margin
        return observation, reward, terminated, truncated, info


@cache
def velocity_env_class(base_env_id: str) -> type[gym.Env]:
    """The cost-adding subclass of the Gymnasium env registered as ``base_env_id``."""
    base = load_env_creator(gym.spec(base_env_id).entry_point)
    name = f"SafetyVelocity{base.__name__}_{base_env_id.split('-')[-1]}"
    return type(name, (VelocityCostMixin, base), {"__module__": __name__})


def make_velocity_gym_env(*, base_env_id: str, **kwargs: Any) -> gym.Env:
    """Gymnasium entry point of every registered velocity task."""
    return velocity_env_class(base_env_id)(**kwargs)


# Gymnasium reads render modes from the entry point's ``metadata`` before building the env.
make_velocity_gym_env.metadata = {"render_modes": ["human", "rgb_array", "depth_array"]}


def register_velocity_tasks() -> None:
    """Register every velocity id with Gymnasium (idempotent; runs on import)."""
    for env_id, registered in VELOCITY_REGISTRATIONS.items():
        if env_id in gym.registry:
            continue
        task = registered.task
        gym.register(
            id=env_id,
            entry_point=make_velocity_gym_env,
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={
                "base_env_id": task.base_env_id(registered.mujoco_version),
                "cost_threshold": task.threshold,
                "cost_speed": task.speed,
            },
        )
