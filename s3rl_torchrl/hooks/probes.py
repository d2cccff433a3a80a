"""The linear probes of the policy encoder at each epoch's end (``diagnostics.probes``).

Does the encoder separate safe from unsafe states (S3RL's claim, Figure 4)? A logistic
regression on a class-balanced replay sample: ``probe/accuracy``, ``probe/auc``. Does it order
states by a graded label (the run's contrasted one, or the cost-to-go)? A linear regression on
a bin-balanced replay sample: ``probe/spearman``, ``probe/r2`` (held-out, NaN while a class or
bin is missing; ``diagnostics/probe.py``). Each epoch draws its sample with its own seed and
none of the training streams.
"""

from __future__ import annotations

from typing import Any

from tensordict.nn import TensorDictModuleBase
from torchrl.data import TensorDictReplayBuffer

from s3rl_torchrl.algorithms.contrastive import SAFE_LABEL_KEY
from s3rl_torchrl.diagnostics.probe import replay_graded_probe, replay_probe
from s3rl_torchrl.hooks.base import HookHost, TrainerHook
from s3rl_torchrl.hooks.labels import GradedLabels
from s3rl_torchrl.modules import get_policy_encoder

__all__ = ["LinearProbes"]


class LinearProbes(TrainerHook):
    """The binary and the graded probe on ``actor``'s policy encoder, on samples of
    ``replay_buffer`` (off-policy: the replay buffer; on-policy: the FIFO of labelled states);
    ``labels`` is the run's graded label, which the graded probe reads. ``seed``: the run's;
    epoch ``e`` draws with ``seed * 1_000_003 + e``."""

    def __init__(
        self,
        replay_buffer: TensorDictReplayBuffer,
        actor: TensorDictModuleBase,
        labels: GradedLabels,
        seed: int,
    ) -> None:
        self.replay_buffer, self.actor, self.labels, self.seed = replay_buffer, actor, labels, seed

    def register(self, host: HookHost, name: str) -> None:
        host.register_op("after_evaluation", self.measure)

    def measure(self, row: dict[str, Any]) -> dict[str, float]:
        seed = self.seed * 1_000_003 + row["epoch"]
        encoder = get_policy_encoder(self.actor)
        binary = replay_probe(self.replay_buffer, encoder, seed=seed, label_key=SAFE_LABEL_KEY)
        graded = replay_graded_probe(
            self.replay_buffer,
            encoder,
            seed=seed,
            label_key=self.labels.key,
            bin_edges=self.labels.bins,
        )
        return {
            "probe/accuracy": binary.accuracy,
            "probe/auc": binary.auc,
            "probe/spearman": graded.spearman,
            "probe/r2": graded.r2,
        }
