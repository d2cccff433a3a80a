"""Bullet-Safety-Gym's Run and Circle tasks, from the upstream ``bullet-safety-gym`` package.

Importing ``bullet_safety_gym`` registers ``SafetyBallRun-v0`` and the others with Gymnasium
itself. This package registers each task a second time under its own namespace,
``s3rl_torchrl/SafetyBallRun-v0`` (no clash with the upstream id), without importing
``bullet_safety_gym``: the entry point :func:`make_bullet_env` imports it only when an env is
built, so ``import s3rl_torchrl`` works without the optional package. The task name users pass
(``make_env("SafetyBallRun-v0")``, ``task=SafetyBallRun-v0``) is the upstream id.

:func:`make_bullet_env` builds exactly the upstream env (its registered entry point and kwargs)
and adds two things, neither of which changes the dynamics, reward or cost:

- bullet-safety-gym 1.4.0's ``reset(seed=...)`` ignores the seed; the tasks draw their random
  start (spawn position, yaw, joint noise) from NumPy's *global* generator.
  :class:`NumpyGlobalSeeding` gives each env its own seeded generator instead.
- it silences PyBullet's start-up banner by flushing C's ``stdout``/``stderr`` looked up by the
  Python stream's *name*, which fails when ``sys.stdout``/``sys.stderr`` are replaced (pytest's
  capture, notebooks); the upstream import and construction run with the process's own streams.

bullet-safety-gym pins ``gymnasium~=0.28.1`` but runs unchanged on Gymnasium 1.x for these
tasks; it is installed with ``pip install --no-deps`` (``docs/installation.md``).
Episode lengths, observation sizes and cost rules are those of bullet-safety-gym 1.4.0
(``bullet_safety_gym/__init__.py`` registrations; ``envs/tasks.py`` ``RunTask`` and
``CircleTask``; ``envs/agents.py`` velocity constraints); ``tests/envs/test_bullet.py`` checks
them against the installed package.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator

from s3rl_torchrl.envs.spec import TaskSpec

BULLET_SOURCE = "bullet-safety-gym 1.4.0"
BULLET_MODULE = "bullet_safety_gym"
BULLET_ENV_MODULE = "bullet_safety_gym.envs.builder"
NAMESPACE = "s3rl_torchrl"


class NumpyGlobalSeeding(gym.Wrapper):
    """Gives an upstream Bullet env its own seeded NumPy generator for ``reset``.

    bullet-safety-gym draws its random start from ``np.random`` (the global generator) and
    ignores ``reset(seed=...)``. During ``reset`` this wrapper swaps its own ``RandomState`` in as
    the global state and back out afterwards, so ``reset(seed=s)`` draws exactly what
    ``np.random.seed(s); env.reset()`` draws on the plain upstream env, copies of a vector env
    do not share one stream, and code outside the env sees the global generator untouched.
    Steps draw no random numbers in the Run and Circle tasks (checked by the tests), so ``step``
    is passed through as is.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self._random_state = np.random.RandomState()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            self._random_state = np.random.RandomState(seed)
        outside = np.random.get_state()
        np.random.set_state(self._random_state.get_state())
        try:
            return self.env.reset(seed=seed, options=options)
        finally:
            self._random_state.set_state(np.random.get_state())
            np.random.set_state(outside)


@contextmanager
def _process_std_streams() -> Iterator[None]:
    """Run with ``sys.stdout``/``sys.stderr`` set to the process's own streams."""
    saved = sys.stdout, sys.stderr
    sys.stdout = sys.__stdout__ or saved[0]
    sys.stderr = sys.__stderr__ or saved[1]
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved


def import_bullet_safety_gym():
    """Import the upstream package (it registers its ids) and its env module (needs pybullet)."""
    if sys.modules.get(BULLET_ENV_MODULE) is None:
        with _process_std_streams():
            importlib.import_module(BULLET_ENV_MODULE)
    return sys.modules[BULLET_MODULE]


class RgbArrayRender(gym.Wrapper):
    """Gymnasium's ``render()`` (``render_mode="rgb_array"``) on an upstream Bullet env, whose
    own ``render(mode=...)`` takes the old Gym argument (and opens PyBullet's GUI without one).
    Frames come from PyBullet's CPU renderer (TinyRenderer: no OpenGL, no display), from the
    task's own camera (the Run tasks' follows the agent), ``width`` x ``height`` pixels."""

    def __init__(self, env: gym.Env, width: int | None = None, height: int | None = None):
        super().__init__(env)
        camera = env.unwrapped.world.camera
        camera.render_width = width or camera.render_width
        camera.render_height = height or camera.render_height
        self._render_mode = "rgb_array"
        # The simulated rate (upstream declares none; Gymnasium's checker warns without it).
        self.metadata = {**env.metadata, "render_fps": round(1 / env.unwrapped.dt)}

    @property
    def render_mode(self) -> str:
        return self._render_mode

    def render(self) -> np.ndarray:
        return np.ascontiguousarray(self.env.unwrapped.render(mode="rgb_array"), dtype=np.uint8)


def make_bullet_env(
    *,
    upstream_id: str,
    render_mode: str | None = None,
    width: int | None = None,
    height: int | None = None,
    **kwargs: Any,
) -> gym.Env:
    """Gymnasium entry point of ``s3rl_torchrl/<upstream_id>``: the upstream env, seedable.

    ``kwargs`` override the upstream registration's kwargs (e.g. ``debug=True``).
    ``render_mode="rgb_array"`` renders frames of ``width`` x ``height`` (upstream: 480 x 360)
    through :class:`RgbArrayRender`; ``"human"`` is upstream's PyBullet GUI (needs a display).
    """
    import_bullet_safety_gym()
    upstream = gym.spec(upstream_id)
    with _process_std_streams(), warnings.catch_warnings():
        # Its float32 observation bounds in a float64 Box: NumPy warns casting the dtype limits.
        warnings.filterwarnings("ignore", "overflow encountered in cast", RuntimeWarning)
        env = load_env_creator(upstream.entry_point)(**{**upstream.kwargs, **kwargs})
    if render_mode == "human":
        env.render(mode="human")  # upstream: reconnects PyBullet with its GUI
    env = NumpyGlobalSeeding(env)
    if render_mode == "rgb_array":
        env = RgbArrayRender(env, width, height)
    return env


# Gymnasium reads render modes from the entry point's ``metadata`` before building the env.
make_bullet_env.metadata = {"render_modes": ["human", "rgb_array"]}


def register_bullet_tasks() -> None:
    """Register ``s3rl_torchrl/<id>`` for every Bullet task (idempotent; runs on import)."""
    for spec in BULLET_TASKS:
        if spec.registered_as in gym.registry:
            continue
        gym.register(
            id=spec.registered_as,
            entry_point=f"{__name__}:make_bullet_env",
            max_episode_steps=spec.max_episode_steps,
            kwargs={"upstream_id": spec.env_id},
        )


def _bullet_task(
    name: str, steps: int, obs_dim: int, act_dim: int, cost_rule: str
) -> TaskSpec:
    return TaskSpec(
        env_id=name,
        family="bullet",
        source=BULLET_SOURCE,
        max_episode_steps=steps,
        cost_limit=10.0,  # the paper's Table 3 default, for every task
        obs_dim=obs_dim,
        act_dim=act_dim,
        cost_rule=cost_rule,
        extra="bullet",
        registered_as=f"{NAMESPACE}/{name}",
        requires_module=BULLET_MODULE,
    )


def _run_rule(speed_limit: float) -> str:
    return f"1 if |y| > 2 or sqrt(vx^2 + vy^2) > {speed_limit}"


_CIRCLE_RULE = "1 if |x| > 6"

#: The eight Run and Circle tasks of bullet-safety-gym (episode length, obs/act size, cost).
BULLET_TASKS: tuple[TaskSpec, ...] = (
    _bullet_task("SafetyBallRun-v0", 100, 7, 2, _run_rule(2.5)),
    _bullet_task("SafetyCarRun-v0", 200, 7, 2, _run_rule(1.5)),
    _bullet_task("SafetyDroneRun-v0", 200, 17, 4, _run_rule(1.5)),
    _bullet_task("SafetyAntRun-v0", 200, 33, 8, _run_rule(1.5)),
    _bullet_task("SafetyBallCircle-v0", 200, 8, 2, _CIRCLE_RULE),
    _bullet_task("SafetyCarCircle-v0", 300, 8, 2, _CIRCLE_RULE),
    _bullet_task("SafetyDroneCircle-v0", 300, 18, 4, _CIRCLE_RULE),
    _bullet_task("SafetyAntCircle-v0", 500, 34, 8, _CIRCLE_RULE),
)
