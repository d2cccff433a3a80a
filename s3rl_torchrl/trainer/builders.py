"""Build a run's components from its :class:`TrainConfig`: the envs, the labelled buffer, the
agent (its algorithm family's, ``s3rl_torchrl/algorithms/``) and what the family's update
schedule stores and samples.

Each builder returns a plain TorchRL object, so a user can take one piece into their own loop.
"""

from __future__ import annotations

import torch
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs import EnvBase

from s3rl_torchrl.algorithms import Agent, Networks, family_of
from s3rl_torchrl.algorithms import build_agent as build_family_agent
from s3rl_torchrl.algorithms.agent import CompileFn
from s3rl_torchrl.algorithms.config import AlgoConfig
from s3rl_torchrl.algorithms.contrastive import SAFE_LABEL_KEY, contrastive_sampler
from s3rl_torchrl.algorithms.schedule import ReplayUpdates, RolloutUpdates
from s3rl_torchrl.data import GatherStorage
from s3rl_torchrl.envs import make_env
from s3rl_torchrl.hooks import GradedLabels
from s3rl_torchrl.modules import get_policy_encoder
from s3rl_torchrl.trainer.config import TrainConfig

__all__ = [
    "build_agent",
    "build_envs",
    "build_replay_buffer",
    "build_updates",
    "set_torch_threads",
]


def build_envs(cfg: TrainConfig, labels: GradedLabels | None = None) -> tuple[EnvBase, EnvBase]:
    """Training envs and separate test envs (seeded apart so they never share episodes). The
    training envs also read the task's graded margin when ``labels`` store it (a training-only
    label, never in the observation)."""
    train_env = make_env(
        cfg.task.name,
        num_envs=cfg.collector.num_envs,
        seed=cfg.seed,
        device=cfg.device,
        batching=cfg.collector.batching,
        margin=labels is not None and labels.reads_margin,
    )
    test_env = make_env(
        cfg.task.name,
        num_envs=cfg.eval.num_envs,
        seed=cfg.seed + 100_000,
        device=cfg.device,
        batching=cfg.collector.batching,
    )
    return train_env, test_env


def build_replay_buffer(algo: AlgoConfig) -> TensorDictReplayBuffer:
    """One storage for everything; the sampler keeps the label partition as it writes.

    Off-policy: the replay buffer the gradient steps sample. On-policy: the FIFO of the last
    ``buffer_size`` labelled states, for the contrastive phase and the probes only.
    ``GatherStorage``: torchrl's storage with a faster gather of each sampled batch.
    """
    return TensorDictReplayBuffer(
        storage=GatherStorage(algo.buffer_size),
        sampler=contrastive_sampler(algo.contrastive_cfg, algo.contrastive),
        batch_size=algo.batch_size,
    )


def build_agent(
    cfg: TrainConfig,
    env: EnvBase,
    replay_buffer: TensorDictReplayBuffer | None,
    compile_fn: CompileFn | None = None,
) -> Agent:
    """The run's agent: its family's actor, critics, loss, optimisers and gradient step, with
    the Lagrangian and the contrastive phase (sampling ``replay_buffer``).

    ``compile_fn`` (e.g. ``torch.compile``) wraps the SAC family's loss calls.
    """
    nets = Networks(
        cfg.network, env.observation_spec["observation"].shape[-1], env.action_spec_unbatched
    )
    family = family_of(cfg.algo)
    return build_family_agent(
        family, cfg.algo, nets, cfg.task.cost_limit, replay_buffer, compile_fn
    )


def build_updates(
    cfg: TrainConfig,
    agent: Agent,
    replay_buffer: TensorDictReplayBuffer,
    labels: GradedLabels | None = None,
) -> ReplayUpdates | RolloutUpdates:
    """The run-time side of the family's update schedule (``algorithms/schedule.py``).

    ``replay_buffer`` keeps, besides what the gradient steps read, the labelled keys: the
    sampler's label, the binary label, the graded one (``labels``), the policy encoder's inputs
    and what the contrastive loss reads (the contrastive phase and the probes embed them).
    """
    keys = [replay_buffer.sampler.label_key, SAFE_LABEL_KEY]
    keys += [labels.key] if labels is not None else []
    keys += get_policy_encoder(agent.actor).in_keys
    phase = agent.contrastive
    if phase is not None:
        role = phase.loss.tensor_keys.contrastive_role  # written by the sampler per batch
        keys += [key for key in phase.loss.in_keys if key != role]
    # Labels describe their own step: n-step returns keep them at t (a graded one as the binary).
    keep_at_t = ("safe",) + ((labels.key[-1],) if labels is not None else ())
    schedule = family_of(cfg.algo).schedule(cfg.collector, cfg.algo)
    return schedule.updates(
        agent.loss, replay_buffer, list(dict.fromkeys(keys)), keep_at_t, agent.prepare
    )


def set_torch_threads(threads: int) -> None:
    if threads > 0:
        torch.set_num_threads(threads)
