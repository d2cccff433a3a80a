"""``make_env``: any registered task as a TorchRL env carrying ``("next", "cost")``."""

from __future__ import annotations

import importlib
import math
from functools import partial
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import (
    DoubleToFloat,
    EnvBase,
    GymEnv,
    GymWrapper,
    InitTracker,
    ParallelEnv,
    RewardSum,
    SerialEnv,
    StepCounter,
    TransformedEnv,
)
from torchrl.envs.gym_like import BaseInfoDictReader

from s3rl_torchrl.envs.bullet import import_bullet_safety_gym
from s3rl_torchrl.envs.registry import get_task
from s3rl_torchrl.envs.spec import EXTRA_INSTALL, TaskSpec
from s3rl_torchrl.transforms import CostLabel, EpisodeSum

Batching = Literal["sync_vector", "async_vector", "serial", "parallel"]
BATCHING_CHOICES: tuple[str, ...] = ("sync_vector", "async_vector", "serial", "parallel")


class CostInfoReader(BaseInfoDictReader):
    """Reads ``info["cost"]`` into a float32 ``"cost"`` entry shaped like torchrl's reward.

    A reset's info has no cost: it reads as 0. Gymnasium vector envs give one cost per copy.
    With ``margin=True`` it also reads the task's graded margin ``info["cost_margin"]``
    (:attr:`~s3rl_torchrl.envs.TaskSpec.margin_rule`) into ``"margin"``, the same shape; a
    reset's info has none and reads as NaN (no step, no margin: nothing labels the reset row).
    """

    def __init__(self, batch_size: tuple[int, ...] = (), *, margin: bool = False):
        self.batch_size = torch.Size(batch_size)
        self.margin = bool(margin)
        entries = {"cost": Unbounded(shape=(*self.batch_size, 1), dtype=torch.float32)}
        if self.margin:
            entries["margin"] = Unbounded(shape=(*self.batch_size, 1), dtype=torch.float32)
        self._info_spec = Composite(**entries, shape=self.batch_size)

    def __call__(self, info_dict: dict[str, Any], tensordict: TensorDictBase) -> TensorDictBase:
        cost = info_dict.get("cost")
        shape = (*tensordict.shape, 1)
        if cost is None:
            value = torch.zeros(shape, dtype=torch.float32, device=tensordict.device)
        else:
            value = torch.as_tensor(np.asarray(cost, dtype=np.float32), device=tensordict.device)
            value = value.reshape(shape)
        tensordict.set("cost", value)
        if self.margin:
            margin = info_dict.get("cost_margin")
            if margin is None:
                value = torch.full(shape, math.nan, dtype=torch.float32, device=tensordict.device)
            else:
                value = torch.as_tensor(
                    np.asarray(margin, dtype=np.float32), device=tensordict.device
                ).reshape(shape)
            tensordict.set("margin", value)
        return tensordict

    @property
    def info_spec(self) -> Composite:
        return self._info_spec


def require_task_module(spec: TaskSpec) -> None:
    """Import the module that registers ``spec``'s id, naming the pip extra if it is missing."""
    if spec.requires_module is None:
        return
    try:
        if spec.family == "bullet":
            import_bullet_safety_gym()
        else:
            importlib.import_module(spec.requires_module)
    except ImportError as error:
        hint = EXTRA_INSTALL.get(spec.extra or "", f"pip install {spec.requires_module}")
        raise ImportError(
            f"Task {spec.env_id!r} needs the optional package {spec.requires_module!r} "
            f"(extra {spec.extra!r}), which cannot be imported ({error}). Install it with: {hint}"
        ) from error


def make_base_env(
    task: str,
    num_envs: int = 0,
    device: str | torch.device = "cpu",
    *,
    vectorization: Literal["sync", "async"] = "sync",
    margin: bool = False,
    **gym_kwargs: Any,
) -> GymWrapper:
    """A registered task as a plain torchrl Gym env with the cost read from ``info``.

    ``num_envs=0`` wraps one Gymnasium env; ``num_envs >= 1`` wraps a Gymnasium vector env of
    that many copies (``vectorization="sync"``: one process; ``"async"``: one process per copy).
    Vector envs run with ``AutoresetMode.DISABLED`` so that torchrl, not Gymnasium, decides
    when a copy resets (torchrl's own reset semantics, no lost final observation).
    ``margin=True`` also reads the task's graded margin into ``"margin"`` (:class:`CostInfoReader`).
    """
    spec = get_task(task)  # fail early, listing the valid names
    require_task_module(spec)
    if margin:
        require_margin(spec)
    if num_envs == 0:
        # GymEnv, not GymWrapper(gym.make(...)): it takes torchrl's own options too
        # (from_pixels, pixels_only, frame_skip) and passes the rest to gymnasium.make.
        env = GymEnv(spec.gym_id, device=device, **gym_kwargs)
    else:
        vector_env = gym.make_vec(
            spec.gym_id,
            num_envs=num_envs,
            vectorization_mode=vectorization,
            vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.DISABLED},
            **gym_kwargs,
        )
        env = GymWrapper(vector_env, device=device)
    return env.set_info_dict_reader(CostInfoReader(env.batch_size, margin=margin))


def require_margin(spec: TaskSpec) -> None:
    """Fail, naming the tasks that have one, when ``spec`` exposes no graded margin."""
    if spec.margin_rule is None:
        from s3rl_torchrl.envs.registry import TASKS

        families = sorted({t.family for t in TASKS.values() if t.margin_rule})
        raise ValueError(
            f"Task {spec.env_id!r} exposes no graded safety margin (info['cost_margin']); the "
            f"tasks of the {' and '.join(families)} families do."
        )


def make_env(
    task: str,
    num_envs: int = 1,
    seed: int | None = None,
    device: str | torch.device = "cpu",
    *,
    batching: Batching = "sync_vector",
    cost_label: bool = True,
    margin: bool = False,
    **gym_kwargs: Any,
) -> TransformedEnv:
    """Build a registered task (any family) as a TorchRL env.

    Step tensordicts carry ``("next", "reward")`` and ``("next", "cost")`` (both ``[..., 1]``
    float32), float32 ``observation``, ``step_count``, ``episode_reward``, ``episode_cost``,
    ``is_init`` and, with ``cost_label``, the boolean ``("next", "safe")``.

    Args:
        task: a registered id, e.g. ``"SafetyHalfCheetahVelocity-v1"`` or
            ``"SafetyBallRun-v0"`` (see :func:`s3rl_torchrl.envs.task_names`).
        num_envs: number of copies batched into one env (batch size ``[num_envs]``);
            ``1`` gives an unbatched env.
        seed: seeds the env (each copy gets its own seed derived from it).
        device: device of the output tensordicts.
        batching: how copies are batched when ``num_envs > 1``: ``"sync_vector"`` (default:
            Gymnasium's ``SyncVectorEnv`` in one torchrl env, one process; the fastest on
            2 cores, see ``docs/benchmarks.md``), ``"async_vector"`` (Gymnasium's
            ``AsyncVectorEnv``, one process per copy), ``"serial"`` (torchrl ``SerialEnv``) or
            ``"parallel"`` (torchrl ``ParallelEnv``, one worker process per copy).
        cost_label: append :class:`~s3rl_torchrl.transforms.CostLabel` (``("next", "safe")``).
        margin: also read the task's graded safety margin into ``("next", "margin")`` (float32
            ``[..., 1]``, negative exactly when the step costs; :attr:`TaskSpec.margin_rule`).
            A training-only label: the policy reads ``"observation"`` only. Raises for a task
            without one.
        **gym_kwargs: passed to ``gymnasium.make`` (e.g. ``render_mode="rgb_array"``).
    """
    require_task_module(get_task(task))
    if margin:
        require_margin(get_task(task))
    if not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}.")
    if batching not in BATCHING_CHOICES:
        raise ValueError(
            f"Unknown batching {batching!r}; valid choices are {', '.join(BATCHING_CHOICES)}."
        )

    base: EnvBase
    if num_envs == 1:
        base = make_base_env(task, device=device, margin=margin, **gym_kwargs)
    elif batching in ("sync_vector", "async_vector"):
        vectorization = "sync" if batching == "sync_vector" else "async"
        base = make_base_env(
            task, num_envs, device, vectorization=vectorization, margin=margin, **gym_kwargs
        )
    else:
        create = partial(make_base_env, task, device=device, margin=margin, **gym_kwargs)
        batched_cls = SerialEnv if batching == "serial" else ParallelEnv
        base = batched_cls(num_envs, create, device=device)

    env = TransformedEnv(
        base,
        DoubleToFloat(),
        device=device,
    )
    env.append_transform(StepCounter())
    env.append_transform(InitTracker())
    env.append_transform(RewardSum(in_keys=["reward"], out_keys=["episode_reward"]))
    env.append_transform(EpisodeSum(in_keys=["cost"], out_keys=["episode_cost"]))
    if cost_label:
        env.append_transform(CostLabel())
    if seed is not None:
        env.set_seed(seed)
    return env
