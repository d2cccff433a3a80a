"""Small helpers the Lagrangian losses share: nested ``("next", ...)`` keys, detached parameter
copies and constructor argument checks with errors that name the valid choices."""

from __future__ import annotations

import math

from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torch import Tensor


def next_key(key: NestedKey) -> tuple[str, ...]:
    """``key`` read from the ``"next"`` entry of a transition."""
    return ("next", *key) if isinstance(key, tuple) else ("next", key)


def detached(params: TensorDictBase) -> TensorDictBase:
    """``params.detach()`` without locking the copy: ``detach()`` of locked
    ``TensorDictParams`` locks its result, and tensordict warns about a ``lock_()`` inside a
    compiled graph at every compile of the loss."""
    return params.apply(Tensor.detach, filter_empty=True)


def parameter_containers(*networks: str) -> tuple[str, ...]:
    """The attribute names ``convert_to_functional`` gives the parameters (and target
    parameters) of ``networks``: what a loss's forward passes to ``_clear_weakrefs``."""
    return tuple(f"{prefix}{name}_network_params" for prefix in ("", "target_") for name in networks)


def check_arguments(networks: dict, counts: dict, choices: dict, alpha_init: float) -> None:
    """Constructor arguments: ``networks`` name -> (module or list, the critics it holds),
    ``counts`` name -> (value, lowest allowed), ``choices`` name -> (value, allowed values)."""
    for name, (value, low) in counts.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}.")
    for name, (value, allowed) in choices.items():
        if value not in allowed:
            valid = ", ".join(map(repr, allowed))
            raise ValueError(f"Unknown {name} {value!r}; valid choices are {valid}.")
    if not (alpha_init > 0 and math.isfinite(alpha_init)):
        raise ValueError(f"alpha_init must be a positive finite number, got {alpha_init!r}.")
    for name, (module, expected) in networks.items():
        if isinstance(module, (list, tuple)) and len(module) != expected:
            count = f"{name} is a list of {len(module)} modules; it must hold {expected}"
            raise ValueError(f"{count} (one per cost and critic), or pass one module.")
