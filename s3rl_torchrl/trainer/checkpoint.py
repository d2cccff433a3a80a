"""Checkpoints: written atomically, loaded with ``torch.load(weights_only=True)``.

A checkpoint is a directory ``<run>/checkpoints/latest/`` holding ``state.pt`` (state dicts,
counters, RNG states and the run's config, all plain tensors and containers) and
``replay_buffer/`` (torchrl's ``ReplayBuffer.dumps``). It is written to ``latest.tmp`` and
swapped in by renames, so a crash mid-write leaves the previous checkpoint intact.
"""

from __future__ import annotations

import json
import os
import random
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch

CHECKPOINT_FORMAT = "s3rl-torchrl/1"
STATE_FILE = "state.pt"
REPLAY_DIR = "replay_buffer"
GROUP_FILE = "seeds.json"  # at the root of a multi-seed run: the group's config, seeds included


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, or does not match the current configuration."""


def capture_rng_state() -> dict[str, Any]:
    """torch, numpy and Python RNG states as tensors and lists (safe for ``weights_only``)."""
    kind, keys, pos, has_gauss, cached = np.random.get_state()
    version, internal, gauss = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "numpy": {
            "kind": kind,
            "keys": torch.from_numpy(keys.astype(np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        },
        "python": {"version": version, "internal": list(internal), "gauss": gauss},
    }


def restore_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state(
        (
            n["kind"],
            n["keys"].numpy().astype(np.uint32),
            n["pos"],
            n["has_gauss"],
            n["cached_gaussian"],
        )
    )
    p = state["python"]
    random.setstate((p["version"], tuple(p["internal"]), p["gauss"]))


def save_checkpoint(
    directory: str | Path, state: dict[str, Any], replay_buffer=None, buffers=None
) -> Path:
    """Write ``state`` (and the replay buffer, and ``buffers``: ``{subdirectory: buffer}``,
    e.g. PPO's rollout) to ``directory`` atomically."""
    directory = Path(directory)
    tmp = directory.with_name(directory.name + ".tmp")
    old = directory.with_name(directory.name + ".old")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    torch.save({"format": CHECKPOINT_FORMAT, **state}, tmp / STATE_FILE)
    if replay_buffer is not None:
        replay_buffer.dumps(tmp / REPLAY_DIR)
    for name, buffer in (buffers or {}).items():
        buffer.dumps(tmp / name)
    if directory.exists():
        shutil.rmtree(old, ignore_errors=True)
        os.replace(directory, old)
    os.replace(tmp, directory)
    shutil.rmtree(old, ignore_errors=True)
    return directory


def resolve_checkpoint(path: str | Path) -> Path:
    """Accept a run directory, a checkpoint directory or a ``state.pt`` file."""
    path = Path(path).expanduser()
    candidates = [
        path,
        path / STATE_FILE,
        path / "checkpoints" / "latest" / STATE_FILE,
        path / "checkpoints" / "latest.old" / STATE_FILE,  # a crash between the two renames
    ]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    group_file = path / GROUP_FILE
    if group_file.is_file():
        seeds = json.loads(group_file.read_text())["seeds"]
        raise CheckpointError(
            f"{str(path)!r} is a multi-seed run (seeds {seeds}): resume the group with "
            f"resume={path} 'seeds=[{','.join(map(str, seeds))}]', or name one seed's run "
            f"directory, e.g. {path / f'seed{seeds[0]}'}."
        )
    raise CheckpointError(
        f"No checkpoint found at {str(path)!r}: expected a run directory (with "
        f"checkpoints/latest/{STATE_FILE}), a checkpoint directory, or a {STATE_FILE} file."
    )


def load_checkpoint(path: str | Path) -> tuple[dict[str, Any], Path]:
    """Load a checkpoint safely; returns the state and the checkpoint directory."""
    file = resolve_checkpoint(path)
    try:
        state = torch.load(file, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises several types for truncated or foreign files
        raise CheckpointError(
            f"Checkpoint {str(file)!r} is corrupt or not a s3rl-torchrl checkpoint "
            f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})."
        ) from err
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(
            f"{str(file)!r} is not a s3rl-torchrl checkpoint (format {found!r}, "
            f"expected {CHECKPOINT_FORMAT!r})."
        )
    return state, file.parent


def check_compatible(saved: dict[str, Any], current: dict[str, Any], keys: list[str]) -> None:
    """Fail clearly when a resumed run's config differs where the saved weights depend on it."""

    def get(cfg: dict, dotted: str):
        for part in dotted.split("."):
            cfg = cfg[part]
        return cfg

    diffs = [
        f"{key}: checkpoint has {get(saved, key)!r}, the current config has {get(current, key)!r}"
        for key in keys
        if get(saved, key) != get(current, key)
    ]
    if diffs:
        raise CheckpointError(
            "The checkpoint does not match the current configuration:\n  " + "\n  ".join(diffs)
        )
