"""Fixed layouts for the navigation tasks: ``env.reset(options={"layout": {...}})``.

A layout names where every object of a task starts. The Circle tasks take the robot's pose only
(``{"agent": [x, y, yaw]}``); the Goal task takes every object (``s3rl_torchrl.envs.goal``).
Everything here checks a layout before the physics is touched and fails with an error naming the
problem: the option's or the layout's keys, an entry's shape, a count, a position outside its
placement area, two objects closer than their keep-out radii.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The keys ``reset(options=...)`` reads in the navigation tasks.
RESET_OPTIONS: tuple[str, ...] = ("layout",)


def layout_from_options(options: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    """``options["layout"]`` (``None`` when absent); any other option key is an error."""
    if options is None:
        return None
    if not isinstance(options, Mapping):
        raise TypeError(f"reset options must be a dict, got {type(options).__name__}.")
    unknown = sorted(set(options) - set(RESET_OPTIONS))
    if unknown:
        raise ValueError(
            f"Unknown reset option(s) {', '.join(map(repr, unknown))}; valid options are "
            f"{', '.join(map(repr, RESET_OPTIONS))}."
        )
    layout = options.get("layout")
    if layout is not None and not isinstance(layout, Mapping):
        raise TypeError(f"options['layout'] must be a dict, got {type(layout).__name__}.")
    return layout


def check_keys(layout: Mapping[str, Any], valid: Sequence[str]) -> None:
    """The layout has exactly the keys ``valid``."""
    unknown = sorted(set(layout) - set(valid))
    missing = [k for k in valid if k not in layout]
    if unknown or missing:
        problems = []
        if unknown:
            problems.append(f"unknown key(s) {', '.join(map(repr, unknown))}")
        if missing:
            problems.append(f"missing key(s) {', '.join(map(repr, missing))}")
        raise ValueError(
            f"Bad layout: {' and '.join(problems)}; a layout has exactly the keys "
            f"{', '.join(map(repr, valid))}."
        )


def as_vector(value: Any, where: str, sizes: Sequence[int], meaning: str) -> np.ndarray:
    """``value`` as a float vector of one of ``sizes``, all finite."""
    try:
        vector = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"Bad layout: {where} must be {meaning}, got {value!r}.") from None
    if vector.ndim != 1 or vector.shape[0] not in sizes:
        raise ValueError(f"Bad layout: {where} must be {meaning}, got {value!r}.")
    if not np.all(np.isfinite(vector)):
        raise ValueError(f"Bad layout: {where} must be finite, got {value!r}.")
    return vector


def as_list(value: Any, where: str, count: int, meaning: str) -> list[Any]:
    """``value`` as a list of exactly ``count`` entries."""
    if isinstance(value, np.ndarray):
        value = list(value)
    if not isinstance(value, Sequence) or isinstance(value, str):
        raise ValueError(f"Bad layout: {where} must be a list of {count} {meaning}, got {value!r}.")
    if len(value) != count:
        entries = "entry" if count == 1 else "entries"
        raise ValueError(
            f"Bad layout: {where} must have {count} {entries} ({meaning}), got {len(value)}."
        )
    return list(value)


@dataclass(frozen=True)
class Placed:
    """One object of a layout: its name in messages, position and keep-out radius."""

    name: str
    xy: np.ndarray
    keepout: float


def check_in_area(item: Placed, low: float, high: float, why: str) -> None:
    """``low <= x, y <= high`` (the object's placement area), else an error naming it."""
    x, y = (float(v) for v in item.xy)
    if not (low <= x <= high and low <= y <= high):
        raise ValueError(
            f"Bad layout: {item.name} at ({x:g}, {y:g}) is outside its placement area: x and y "
            f"must lie in [{low:g}, {high:g}] ({why})."
        )


def check_keepouts(items: Sequence[Placed], margin: float = 0.0) -> None:
    """No two objects closer than the sum of their keep-out radii (plus ``margin``).

    Safety-Gymnasium rejects a placement when ``dist < keepout_a + margin + keepout_b``
    (``utils/random_generator.py: sample_layout``), so a distance equal to the sum is allowed.
    """
    for i, first in enumerate(items):
        for second in items[i + 1 :]:
            dist = math.hypot(*(first.xy - second.xy))
            limit = first.keepout + margin + second.keepout
            if dist < limit:
                raise ValueError(
                    f"Bad layout: {first.name} and {second.name} overlap: they are {dist:.4g} "
                    f"apart, less than their keep-out radii {first.keepout:g} + "
                    f"{second.keepout:g} = {limit:g}."
                )
