"""``CostLabel``: the paper's per-transition safety label, ``safe = (cost == 0)``."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Categorical, Composite, TensorSpec
from torchrl.envs.transforms import Transform


def _one_key(
    side: str,
    key: NestedKey | None,
    keys: NestedKey | Sequence[NestedKey] | None,
    default: NestedKey,
) -> NestedKey:
    """The one key given as ``<side>_key`` or as torchrl's ``<side>_keys`` (a one-key list)."""
    if keys is None:
        return default if key is None else key
    if key is not None:
        raise TypeError(f"CostLabel: pass {side}_key or {side}_keys, not both.")
    if isinstance(keys, str | tuple):  # a single (nested) key, as torchrl also accepts
        return keys
    keys = list(keys)
    if len(keys) != 1:
        raise ValueError(
            f"CostLabel writes one label from one cost entry: {side}_keys must hold exactly one "
            f"key, got {keys}."
        )
    return keys[0]


class CostLabel(Transform):
    """Write the boolean safety label of a transition next to its cost.

    ``safe = cost <= threshold`` (the paper's ``safe = (cost == 0)`` with the default
    ``threshold=0``), reduced over the trailing cost dimension so that a transition with
    several costs is safe only if every cost is; the label has shape ``[..., 1]``.

    **Alignment.** The label sits beside the cost, under ``"next"``: the transition
    ``(s_t, a_t, r_t, c_t, s_{t+1})`` is stored with ``("next", "cost") = c_t`` and
    ``("next", "safe") = (c_t == 0)``, and the state this label describes is ``s_t``, the root
    ``"observation"`` of the same row (paper, Algorithm 1: ``l_t = 1[c_t = 0]``).

    Inside an env (``env.append_transform(CostLabel())``) the keys are read relative to the step
    output, so ``"cost"`` -> ``"safe"`` gives ``("next", "safe")`` in step tensordicts; a reset
    writes ``"safe"`` from the reset's cost if it has one, else ``True`` (no step, no cost).
    On replay data, :meth:`forward` reads ``("next", "cost")`` and writes ``("next", "safe")``
    (or the root keys when the tensordict has no ``"next"``).

    Args:
        in_key: the cost key (default ``"cost"``).
        out_key: the label key (default ``"safe"``).
        threshold: the largest cost still called safe (default ``0.0``).
        in_keys, out_keys: torchrl's spelling of ``in_key`` / ``out_key``: a one-key list (or
            one key), e.g. ``CostLabel(in_keys=[("next", "cost")], out_keys=[("next", "safe")])``
            for replay data. Give one spelling or the other, not both.
    """

    def __init__(
        self,
        in_key: NestedKey | None = None,
        out_key: NestedKey | None = None,
        threshold: float = 0.0,
        *,
        in_keys: NestedKey | Sequence[NestedKey] | None = None,
        out_keys: NestedKey | Sequence[NestedKey] | None = None,
    ):
        in_key = _one_key("in", in_key, in_keys, default="cost")
        out_key = _one_key("out", out_key, out_keys, default="safe")
        super().__init__(in_keys=[in_key], out_keys=[out_key])
        self.threshold = float(threshold)

    def _apply_transform(self, cost: torch.Tensor) -> torch.Tensor:
        return (cost <= self.threshold).all(dim=-1, keepdim=True)

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        (in_key,), (out_key,) = self.in_keys, self.out_keys
        cost = tensordict_reset.get(in_key, None)
        if cost is not None:
            tensordict_reset.set(out_key, self._apply_transform(cost))
        else:
            shape = tensordict_reset.shape + self._label_shape()
            tensordict_reset.set(
                out_key, torch.ones(shape, dtype=torch.bool, device=tensordict_reset.device)
            )
        return tensordict_reset

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        (in_key,), _ = self.in_keys, self.out_keys
        next_td = tensordict.get("next", None)
        if isinstance(next_td, TensorDictBase) and in_key in next_td.keys(True):
            self._call(next_td)
            return tensordict
        if in_key in tensordict.keys(True):
            return self._call(tensordict)
        raise KeyError(
            f"CostLabel: no cost entry {in_key!r} under 'next' or at the root of the tensordict; "
            f"its keys are {sorted(map(str, tensordict.keys(True, True)))}."
        )

    def _label_shape(self) -> torch.Size:
        return torch.Size([1])

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        (in_key,), (out_key,) = self.in_keys, self.out_keys
        parent = self.parent
        cost_spec = None
        if parent is not None:
            full = Composite(
                **parent.full_observation_spec, **parent.full_reward_spec, shape=parent.batch_size
            )
            cost_spec = full.get(in_key, None)
        if cost_spec is None:
            cost_spec = observation_spec.get(in_key, None)
        shape = (
            cost_spec.shape[:-1] + (1,)
            if cost_spec is not None
            else observation_spec.shape + self._label_shape()
        )
        observation_spec[out_key] = Categorical(
            2, shape=shape, dtype=torch.bool, device=observation_spec.device
        )
        return observation_spec
