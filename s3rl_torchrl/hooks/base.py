"""The hook protocol the trainer offers (after torchrl's ``TrainerHookBase`` and
``Trainer.register_op``).

A hook's :meth:`TrainerHook.register` calls ``host.register_op(point, op)`` for each point it
acts at, and ``host.register_module(name, self)`` when it has state to checkpoint. The points,
in the order a run meets them, and what their ops take and return:

- ``"after_collect"``: ``op(batch) -> batch``, each collected batch ``[envs, time]`` before it is
  stored; the batch an op returns is the one stored (and given to the next op);
- ``"after_update"``: ``op(losses) -> None``, after each gradient step, with its detached losses;
- ``"after_evaluation"``: ``op(row) -> dict``, at each epoch's end, after the evaluation: the
  columns the op returns are added to the epoch's row (``row`` holds ``frames``, ``epoch``,
  ``grad_steps``, the training and evaluation statistics and the last losses);
- ``"epoch_end"``: ``op(trainer, row) -> None``, after the row is logged and the checkpoint
  written; the one point whose ops get the trainer (a callback may stop the run,
  ``trainer.stop.requested = True``);
- ``"final_evaluation"``: ``op(episodes, max_steps) -> dict[str, EvalResult]``, once after
  training, after the run's own final evaluations: each result is a row of the final table and
  an entry of ``final_eval.json`` under its name.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from torchrl.data import TensorDictReplayBuffer

HOOK_POINTS = (
    "after_collect", "after_update", "after_evaluation", "epoch_end", "final_evaluation"
)


class HookHost(Protocol):
    """What a hook registers with: the trainer (``trainer/loop.py``). ``replay_buffer`` is the
    run's buffer of labelled steps (off-policy: the replay buffer; on-policy: the FIFO of
    recent labelled states)."""

    replay_buffer: TensorDictReplayBuffer

    def register_op(self, point: str, op: Callable) -> None: ...

    def register_module(self, name: str, module: TrainerHook) -> None: ...


class TrainerHook:
    """A hook with state (``state_dict`` / ``load_state_dict``, empty by default). The trainer
    calls ``load_state_dict`` of every registered module when it resumes, after the replay
    buffer is loaded, with the module's saved state (``{}`` for a checkpoint without it)."""

    def register(self, host: HookHost, name: str) -> None:
        raise NotImplementedError

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        pass
