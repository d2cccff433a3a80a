"""Evaluate a saved policy: rebuild the run's actor from its checkpoint and roll it out."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from s3rl_torchrl.envs import get_task, make_env
from s3rl_torchrl.trainer.builders import build_agent, build_replay_buffer
from s3rl_torchrl.trainer.checkpoint import CheckpointError, load_checkpoint
from s3rl_torchrl.trainer.config import TrainConfig
from s3rl_torchrl.trainer.evaluation import EvalResult, evaluate, record_video


def load_policy(checkpoint: str | Path):
    """The trained actor of a checkpoint and the run's config (a :class:`TrainConfig`)."""
    state, _ = load_checkpoint(checkpoint)
    try:
        cfg: TrainConfig = OmegaConf.to_object(
            OmegaConf.merge(OmegaConf.structured(TrainConfig), state["config"])
        )
    except Exception as err:
        raise CheckpointError(f"The checkpoint's config does not load: {err}") from err
    env = make_env(cfg.task.name, seed=0)
    agent = build_agent(cfg, env, build_replay_buffer(cfg.algo))
    try:
        agent.loss.load_state_dict(state["loss"])
    except RuntimeError as err:
        raise CheckpointError(f"The checkpoint's weights do not fit its own config: {err}") from err
    env.close()
    return agent.actor, cfg


def evaluate_checkpoint(
    checkpoint: str | Path,
    episodes: int = 10,
    num_envs: int = 2,
    seed: int = 0,
    max_steps: int | None = None,
    video_path: str | Path | None = None,
) -> tuple[EvalResult, TrainConfig]:
    """Deterministic evaluation of a checkpoint on fresh test envs (and an optional video).

    ``max_steps=None`` rolls out the task's episode length (the registry's).
    """
    actor, cfg = load_policy(checkpoint)
    if max_steps is None:
        max_steps = get_task(cfg.task.name).max_episode_steps
    env = make_env(cfg.task.name, num_envs=num_envs, seed=seed)
    result = evaluate(env, actor, episodes, max_steps)
    env.close()
    if video_path is not None:
        video_env = make_env(cfg.task.name, seed=seed, from_pixels=True, pixels_only=False)
        record_video(video_env, actor, video_path, max_steps)
        video_env.close()
    return result, cfg
