"""Exact snapshots of a ``make_env`` env, so that a resumed run continues the same episodes.

A checkpoint that holds only the networks restarts every episode at resume: the run that
follows differs from the uninterrupted one. :func:`env_snapshot` captures, for every Gymnasium
copy inside a ``make_env`` env, what its next steps depend on:

- MuJoCo's whole ``MjData`` (its own serialisation: positions, velocities, warm start, contacts
  and every derived quantity the next step reads), and, for the tasks that move bodies at reset
  (the Goal task's layout), the model fields they change;
- the env's random generator (``np_random``) and any generator of its own (the Goal task's);
- the episode's counters in Gymnasium's wrappers (``TimeLimit``'s elapsed steps, whether
  ``reset`` was called);
- the Python state a task keeps between steps (``snapshot_extra`` / ``restore_extra`` of the
  unwrapped env, e.g. the Goal task's last distance to the goal).

:func:`restore_env` writes it back into an env built by the same ``make_env`` call. The
snapshot is plain tensors, numbers and strings (``torch.load(weights_only=True)`` reads it).

Tasks whose simulator cannot be restored exactly (the Bullet tasks: pybullet keeps its state in
a physics server) and batchings that hide the copies in other processes (``async_vector``,
``parallel``) have no snapshot: :func:`exact_restore_unsupported` says why, and the trainer
reports it when it resumes such a run.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import torch
from torchrl.envs import EnvBase, TransformedEnv

__all__ = [
    "MUJOCO_VERSION",
    "SnapshotMismatch",
    "env_snapshot",
    "exact_restore_unsupported",
    "generator_state",
    "restore_env",
    "set_generator_state",
    "snapshot_mujoco_problem",
]

SNAPSHOT_VERSION = 1
#: The MuJoCo release this process simulates with, recorded in every snapshot: MuJoCo's
#: serialised ``MjData`` is read only by the release that wrote it.
MUJOCO_VERSION = mujoco.__version__


class SnapshotMismatch(ValueError):
    """A snapshot this env cannot take back (another MuJoCo release, another number of copies,
    another task's state)."""


def snapshot_mujoco_problem(snapshot: dict[str, Any] | None) -> str | None:
    """Why this process cannot restore ``snapshot`` when it was written by another MuJoCo
    release, or None (the same release, no snapshot, or one written before releases were
    recorded: :func:`restore_env` then finds out when MuJoCo refuses it)."""
    written = (snapshot or {}).get("mujoco")
    if written is None or written == MUJOCO_VERSION:
        return None
    return (
        f"its simulator state was written by MuJoCo {written} and this is MuJoCo "
        f"{MUJOCO_VERSION}, which cannot read it: resume with mujoco=={written} (the project "
        "pins its release in constraints.txt), or start the run again"
    )


def _gym_copies(env: EnvBase) -> list[gym.Env] | str:
    """The Gymnasium envs inside a ``make_env`` env, or why they cannot be reached."""
    base = env.base_env if isinstance(env, TransformedEnv) else env
    inner = getattr(base, "_env", None)  # torchrl's GymWrapper keeps the Gymnasium env here
    if isinstance(inner, gym.vector.SyncVectorEnv):
        return list(inner.envs)
    if isinstance(inner, gym.Env):
        return [inner]
    return (
        f"its copies run as {type(inner or base).__name__} (batching other than sync_vector "
        "keeps them in other processes)"
    )


def exact_restore_unsupported(env: EnvBase) -> str | None:
    """Why ``env``'s state cannot be snapshot exactly, or ``None`` if it can."""
    copies = _gym_copies(env)
    if isinstance(copies, str):
        return copies
    for copy in copies:
        unwrapped = copy.unwrapped
        if not isinstance(getattr(unwrapped, "data", None), mujoco.MjData):
            # The task's id (bullet-safety-gym's class is EnvironmentBuilder for every task).
            name = copy.spec.id.rpartition("/")[2] if copy.spec else type(unwrapped).__name__
            return (
                f"{name} is not a MuJoCo env (pybullet keeps its simulator "
                "state in its physics server, which cannot be saved and restored exactly)"
            )
    return None


def generator_state(rng: np.random.Generator | np.random.RandomState) -> dict[str, Any]:
    """A NumPy generator's state as plain numbers and tensors (:func:`set_generator_state`)."""
    if isinstance(rng, np.random.RandomState):
        kind, keys, pos, has_gauss, cached = rng.get_state()
        return {
            "legacy": kind,
            "keys": torch.from_numpy(keys.astype(np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        }
    return {"bit_generator": dict(rng.bit_generator.state)}


def set_generator_state(rng, state: dict[str, Any]) -> None:
    if "legacy" in state:
        rng.set_state(
            (
                state["legacy"],
                state["keys"].numpy().astype(np.uint32),
                state["pos"],
                state["has_gauss"],
                state["cached_gaussian"],
            )
        )
    else:
        rng.bit_generator.state = state["bit_generator"]


def _wrapper_state(copy: gym.Env) -> dict[str, Any]:
    state: dict[str, Any] = {}
    wrapper = copy
    while isinstance(wrapper, gym.Wrapper):
        if isinstance(wrapper, gym.wrappers.TimeLimit):
            state["elapsed_steps"] = wrapper._elapsed_steps
        if isinstance(wrapper, gym.wrappers.OrderEnforcing):
            state["has_reset"] = bool(wrapper._has_reset)
        wrapper = wrapper.env
    return state


def _set_wrapper_state(copy: gym.Env, state: dict[str, Any]) -> None:
    wrapper = copy
    while isinstance(wrapper, gym.Wrapper):
        if isinstance(wrapper, gym.wrappers.TimeLimit):
            wrapper._elapsed_steps = state["elapsed_steps"]
        if isinstance(wrapper, gym.wrappers.OrderEnforcing):
            wrapper._has_reset = state["has_reset"]
        wrapper = wrapper.env


def _copy_snapshot(copy: gym.Env) -> dict[str, Any]:
    env = copy.unwrapped
    blob = env.data.__getstate__()  # MuJoCo's own serialisation of the whole MjData
    state: dict[str, Any] = {
        "data": torch.frombuffer(bytearray(blob), dtype=torch.uint8),
        "np_random": generator_state(env.np_random),
        "wrappers": _wrapper_state(copy),
    }
    extra = getattr(env, "snapshot_extra", None)
    if extra is not None:
        state["extra"] = extra()
    return state


def _restore_copy(copy: gym.Env, state: dict[str, Any]) -> None:
    env = copy.unwrapped
    restore_extra = getattr(env, "restore_extra", None)
    if ("extra" in state) != (restore_extra is not None):
        raise SnapshotMismatch(f"the snapshot does not match {type(env).__name__}'s state")
    if restore_extra is not None:
        restore_extra(state["extra"])  # model fields first: they may recompute constants
    saved = mujoco.MjData.__new__(mujoco.MjData)
    try:
        saved.__setstate__(state["data"].numpy().tobytes())
    except ValueError as err:  # "Invalid serialized mjModel": another release wrote it
        raise SnapshotMismatch(
            f"MuJoCo {MUJOCO_VERSION} cannot read the snapshot's simulator state ({err}); it "
            "was written by another MuJoCo release or is damaged: resume with the release "
            "that wrote it (the project pins it in constraints.txt), or start the run again"
        ) from err
    mujoco.mj_copyData(env.data, env.model, saved)
    set_generator_state(env.np_random, state["np_random"])
    _set_wrapper_state(copy, state["wrappers"])


def env_snapshot(env: EnvBase) -> dict[str, Any] | None:
    """Everything the next steps of ``env``'s copies depend on, or ``None`` when it cannot be
    restored exactly (:func:`exact_restore_unsupported`)."""
    if exact_restore_unsupported(env) is not None:
        return None
    copies = _gym_copies(env)
    return {
        "version": SNAPSHOT_VERSION,
        "mujoco": MUJOCO_VERSION,
        "copies": [_copy_snapshot(c) for c in copies],
    }


def restore_env(env: EnvBase, snapshot: dict[str, Any]) -> None:
    """Write ``snapshot`` (from :func:`env_snapshot` of an env built alike) back into ``env``."""
    reason = exact_restore_unsupported(env)
    if reason is not None:
        raise ValueError(f"this env cannot be restored exactly: {reason}")
    problem = snapshot_mujoco_problem(snapshot)
    if problem is not None:
        raise SnapshotMismatch(f"the env snapshot cannot be restored: {problem}")
    copies = _gym_copies(env)
    if snapshot.get("version") != SNAPSHOT_VERSION or len(snapshot["copies"]) != len(copies):
        raise SnapshotMismatch(
            f"the env snapshot holds {len(snapshot.get('copies', []))} copies (version "
            f"{snapshot.get('version')}); this env has {len(copies)} (version {SNAPSHOT_VERSION})"
        )
    for copy, state in zip(copies, snapshot["copies"], strict=True):
        _restore_copy(copy, state)
