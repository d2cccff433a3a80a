"""The SAC family's critics against what happened, at each epoch's end
(``diagnostics.critics``, on by default; docs/objectives.md, "Critic diagnostics").

The critics are held against the discounted returns of the last finished training episodes
(``critic/*``), and the actor's gradient is split by the term of its loss it comes from, on one
replay batch of 256 (``grad/*``), drawn with its own seed under ``torch.random.fork_rng()``: the
diagnostics change nothing that is trained. The episodes are the hook's state, in the
checkpoint.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictReplayBuffer

from s3rl_torchrl.diagnostics.critics import (
    RecentEpisodes,
    actor_gradient_norms,
    critic_calibration,
)
from s3rl_torchrl.hooks.base import HookHost, TrainerHook
from s3rl_torchrl.objectives import SACLagLoss

__all__ = ["CriticDiagnostics"]

# Finished training episodes the critic calibration reads each epoch.
CALIBRATION_EPISODES = 10
# The replay batch the actor's gradient norms are measured on.
GRADIENT_BATCH = 256


class CriticDiagnostics(TrainerHook):
    """``critic/*`` and ``grad/*`` columns for a ``SACLagLoss`` (``loss``) with discount
    ``gamma``, sampling ``replay_buffer``; epoch ``e`` draws its batch with
    ``seed * 1_000_003 + e``."""

    def __init__(
        self, loss: SACLagLoss, replay_buffer: TensorDictReplayBuffer, gamma: float, seed: int
    ) -> None:
        self.loss, self.replay_buffer, self.gamma, self.seed = loss, replay_buffer, gamma, seed
        self.recent_episodes = RecentEpisodes(CALIBRATION_EPISODES)

    @staticmethod
    def supports(loss) -> bool:
        """Whether ``loss`` has what the diagnostics read: SAC-Lag's critics and actor terms
        (the SAC family's loss)."""
        return isinstance(loss, SACLagLoss)

    def register(self, host: HookHost, name: str) -> None:
        host.register_op("after_collect", self.record)
        host.register_op("after_evaluation", self.measure)
        host.register_module(name, self)

    def record(self, batch: TensorDictBase) -> TensorDictBase:
        self.recent_episodes.extend(batch)
        return batch

    def measure(self, row: dict[str, Any]) -> dict[str, float]:
        out = critic_calibration(self.loss, list(self.recent_episodes.episodes), self.gamma)
        storage = self.replay_buffer.storage
        if len(storage) == 0:
            return {**out, "grad/entropy": math.nan, "grad/reward": math.nan, "grad/cost": math.nan}
        with torch.random.fork_rng():
            torch.manual_seed(self.seed * 1_000_003 + row["epoch"])
            index = torch.randint(len(storage), (GRADIENT_BATCH,))
            out.update(actor_gradient_norms(self.loss, storage[index]))
        return out

    def state_dict(self) -> dict[str, Any]:
        return self.recent_episodes.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state:  # a checkpoint written before the diagnostics existed has no episodes
            self.recent_episodes.load_state_dict(state)
