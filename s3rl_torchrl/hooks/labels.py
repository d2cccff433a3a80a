"""A graded safety label stored with every step (docs/representation.md, "Graded labels").

Two things read one: S3RL's contrastive phase when it contrasts a graded label
(``algo.contrastive_cfg.label``: ``cost_to_go`` or ``margin``, then its sampler partitions the
buffer by the label's bins), and the graded probe (``diagnostics.probes``), which measures that
label, or the cost-to-go for runs that contrast the binary label or none. A run that needs
neither stores no graded label.

- ``cost_to_go`` needs each collected batch's time dimension: :class:`GradedLabels` writes it
  (``transforms.CostToGo``) after each collect, before the batch is stored;
- ``margin`` comes with every step from the training env, built to read it
  (:attr:`GradedLabels.reads_margin`; never into the observation).

Labels describe their own step: the n-step transform keeps them at ``t``
(:attr:`GradedLabels.key`). Labelling changes nothing that is trained: it adds one entry to
each stored step and draws no random numbers.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from tensordict import TensorDict
from tensordict.utils import NestedKey
from torchrl.data import TensorDictReplayBuffer

from s3rl_torchrl.algorithms.config import AlgoConfig, ContrastiveConfig
from s3rl_torchrl.algorithms.contrastive import LABEL_KEYS, SAFE_LABEL_KEY, label_bins
from s3rl_torchrl.hooks.base import HookHost, TrainerHook
from s3rl_torchrl.transforms import CostToGo

__all__ = ["GradedLabels", "graded_label", "probed_label"]


def graded_label(algo: AlgoConfig) -> str | None:
    """The graded label a run's contrastive phase contrasts, None if binary or no phase."""
    c = algo.contrastive_cfg
    return c.label if algo.contrastive and c.graded else None


def probed_label(contrastive: bool, label: str) -> str:
    """The graded label the graded probe measures: the run's contrasted graded label, else
    ``cost_to_go`` (every task has a cost), so that binary runs and baselines are probed on the
    same label as the graded runs they are compared with."""
    return label if contrastive and label != "binary" else "cost_to_go"


class GradedLabels(TrainerHook):
    """Writes ``label`` (``cost_to_go`` or ``margin``) into every collected step.

    Args:
        label: which graded label.
        cfg: its gamma (``label_gamma``, cost-to-go) and bins (``label_bins``).
    """

    def __init__(self, label: str, cfg: ContrastiveConfig) -> None:
        self.label = label
        self.key: NestedKey = LABEL_KEYS[label]
        self.bins = label_bins(cfg, label)
        self._cost_to_go = CostToGo(cfg.label_gamma) if label == "cost_to_go" else None
        self._replay_buffer: TensorDictReplayBuffer | None = None

    @classmethod
    def for_run(cls, algo: AlgoConfig, probes: bool) -> GradedLabels | None:
        """The run's graded label: the contrasted one, else the probed one when the probes run,
        else None."""
        label = graded_label(algo)
        if label is None and probes:
            label = probed_label(algo.contrastive, algo.contrastive_cfg.label)
        return None if label is None else cls(label, algo.contrastive_cfg)

    @property
    def reads_margin(self) -> bool:
        """The training env must read the task's margin into ``("next", "margin")``."""
        return self.label == "margin"

    def register(self, host: HookHost, name: str) -> None:
        """Labels each collected batch (cost-to-go); the host's ``replay_buffer`` is where the
        label is stored (a buffer without it gets it on resume, :meth:`load_state_dict`)."""
        self._replay_buffer = host.replay_buffer
        if self._cost_to_go is not None:
            host.register_op("after_collect", self._cost_to_go)
        host.register_module(name, self)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """No state of its own. A buffer written by a run that stored no graded label (or
        another one) gets a NaN label for its stored steps, which the graded probe leaves out:
        the run resumes, and its new steps carry the label. Nothing else in the buffer
        changes."""
        storage = self._replay_buffer.storage
        if not storage.initialized or len(storage) == 0:
            return
        stored = storage.get(torch.arange(len(storage)))
        if self.key in stored.keys(include_nested=True):
            return
        like = stored.get(SAFE_LABEL_KEY)
        nan = TensorDict({self.key: torch.full(like.shape, math.nan)}, [len(storage)])
        # set_cursor=False: the stored steps get the entry, the storage's length and the
        # writer's position stay as they are.
        storage.set(torch.arange(len(storage)), nan, set_cursor=False)
