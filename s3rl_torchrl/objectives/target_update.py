"""Soft (Polyak) target update in one fused call over all target leaves."""

from __future__ import annotations

import torch
from torch import Tensor
from torchrl.objectives import SoftUpdate

__all__ = ["ForeachSoftUpdate"]


class ForeachSoftUpdate(SoftUpdate):
    r"""torchrl's :class:`~torchrl.objectives.SoftUpdate` with one ``torch._foreach_lerp_``.

    Same targets, same arithmetic (``theta' <- lerp(theta', theta, tau)``, as ``SoftUpdate``),
    same construction (``ForeachSoftUpdate(loss, tau=0.05)``), ``init_``, ``state_dict`` and
    ``load_state_dict``. ``SoftUpdate.step`` walks the parameter tensordicts and lerps them one
    by one; with the four critics of :class:`~s3rl_torchrl.objectives.SACLagLoss` that measured
    several times the cost of this class (``research/studies/target_update.py``).

    The leaves are listed once, by :meth:`init_`, from ``SoftUpdate``'s own source and target
    tensordicts (which it also keeps from ``init_`` on), so both classes update the same tensors.
    """

    def init_(self) -> None:
        super().init_()
        self._source_leaves: list[Tensor] = []
        self._target_leaves: list[Tensor] = []
        for key, source in self._sources.items(True, True):
            if not isinstance(key, tuple):
                key = (key,)
            self._source_leaves.append(source)
            self._target_leaves.append(self._targets.get(("target_" + key[0], *key[1:])))

    def step(self) -> None:
        if not self.initialized:
            raise RuntimeError(
                f"{type(self).__name__} must be initialized (`init_()`) before calling step()."
            )
        if any(target.requires_grad for target in self._target_leaves):
            raise RuntimeError("the target parameter is part of a graph.")
        with torch.no_grad():
            torch._foreach_lerp_(self._target_leaves, self._source_leaves, 1 - self.eps)
