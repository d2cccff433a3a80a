"""Policy-encoder embeddings of the states a checkpoint visits in evaluation (Figure 4)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from s3rl_torchrl.envs import get_task, make_env
from s3rl_torchrl.modules import get_policy_encoder
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy

__all__ = ["RolloutEmbeddings", "rollout_embeddings"]


@dataclass
class RolloutEmbeddings:
    embeddings: np.ndarray  # [N, d] policy-encoder outputs z = f(s_t)
    safe: np.ndarray  # [N] bool: cost_t == 0 (the label of s_t, as in the replay buffer)
    cost: np.ndarray  # [N] cost_t


def rollout_embeddings(
    checkpoint: str | Path, episodes: int = 2, max_steps: int | None = None, seed: int = 0
) -> RolloutEmbeddings:
    """Roll a checkpoint's policy out deterministically and embed every visited state.

    ``episodes`` env copies run ``max_steps`` steps each (None: the task's episode length) on
    fresh test envs (an episode that ends early is reset and continues, so every copy gives
    ``max_steps`` states). Each state
    ``s_t`` is labelled safe when the step taken from it costs nothing (``CostLabel``).
    """
    actor, cfg = load_policy(checkpoint)
    if max_steps is None:
        max_steps = get_task(cfg.task.name).max_episode_steps
    encoder = get_policy_encoder(actor)
    env = make_env(cfg.task.name, num_envs=episodes, seed=seed)
    try:
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            rollout = env.rollout(max_steps, actor, break_when_any_done=False)
            states = rollout.reshape(-1)
            z = encoder(states.select(*encoder.in_keys).clone()).get(encoder.out_keys[0])
    finally:
        env.close()
    return RolloutEmbeddings(
        embeddings=z.cpu().numpy(),
        safe=states["next", "safe"].reshape(-1).cpu().numpy(),
        cost=states["next", "cost"].sum(-1).reshape(-1).cpu().numpy(),
    )
