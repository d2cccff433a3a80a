"""Checkpoints: written atomically, verified at load, read with ``torch.load(weights_only=True)``.

A checkpoint is a directory ``<run>/checkpoints/latest/`` holding ``state.pt`` (state dicts,
counters, RNG states and the run's config, all plain tensors and containers),
``replay_buffer/`` (torchrl's ``ReplayBuffer.dumps``) and ``manifest.json``: the size and
SHA-256 of every other file. It is written to ``latest.tmp`` (the manifest last) and swapped in
by renames, so a crash mid-write leaves the previous checkpoint intact.

Nothing a checkpoint holds is trusted unchecked: torchrl maps a truncated buffer file and reads
zeros past its end, so a damaged buffer would resume and train on zero observations.
:func:`load_checkpoint` therefore checks every file against the manifest before anything is
read; a missing, truncated, altered or foreign file is a one-line :class:`CheckpointError`
naming it. Checkpoints written before the manifest still load, with an
:class:`UnverifiedCheckpointWarning`, after the one check their own files allow (every buffer
file has the size its ``meta.json`` implies).

Writing fails cleanly, never half-way: torchrl writes the buffer through memory-mapped files,
and a full disk there kills the process with ``SIGBUS`` (no exception, no message), so the free
space is checked first; an error of the file system (disk full, read-only, no permission) is a
one-line :class:`CheckpointError` saying where the previous checkpoint is, intact.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import pickle
import random
import re
import shutil
import tempfile
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch

CHECKPOINT_FORMAT = "s3rl-torchrl/1"
STATE_FILE = "state.pt"
REPLAY_DIR = "replay_buffer"
GROUP_FILE = "seeds.json"  # at the root of a multi-seed run: the group's config, seeds included
MANIFEST_FILE = "manifest.json"
MANIFEST_FORMAT = "s3rl-torchrl-manifest/1"
# SHA-256: ~1.3 GB/s with the SHA extensions of current x86 CPUs (measured, hashlib), twice
# blake2b's speed there: a 100 MB buffer costs ~0.1 s at each save and each load.
HASH = "sha256"
HASH_CHUNK = 1 << 20
# The free space a checkpoint needs: its estimated size times SPACE_FACTOR plus SPACE_SLACK
# (file system blocks, the small files, what the estimate misses).
SPACE_FACTOR = 1.25
SPACE_SLACK = 32 * 2**20
SAMPLER_BYTES_PER_ROW = 32  # the sampler's partition or permutation, the writer's cursor


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, cannot be written, or does not match the current
    configuration."""


class UnverifiedCheckpointWarning(UserWarning):
    """A checkpoint written before checkpoints had a manifest: its files cannot be verified."""


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
    e.g. PPO's rollout) to ``directory`` atomically, with its manifest.

    Raises :class:`CheckpointError` (one line, saying where the previous checkpoint is) when
    the disk has too little free space for it, or the file system refuses a write; the
    partial ``<name>.tmp`` is removed and the previous checkpoint is left as it was.
    """
    directory = Path(directory)
    tmp = directory.with_name(directory.name + ".tmp")
    old = directory.with_name(directory.name + ".old")
    # Serialised in memory first: the state's exact size is known before anything is written,
    # and writing bytes fails with an OSError where a full disk fails.
    payload = io.BytesIO()
    torch.save({"format": CHECKPOINT_FORMAT, **state}, payload)
    parts = {REPLAY_DIR: replay_buffer} if replay_buffer is not None else {}
    parts.update(buffers or {})
    try:
        shutil.rmtree(tmp, ignore_errors=True)  # left by a write that was killed
        if directory.exists():  # else ``old`` is the previous checkpoint (a crash mid-swap)
            shutil.rmtree(old, ignore_errors=True)
        needed = required_bytes(payload.getbuffer().nbytes, parts.values())
        _check_free_space(tmp, needed)
        tmp.mkdir(parents=True)
        with open(tmp / STATE_FILE, "wb") as file:
            file.write(payload.getbuffer())
        del payload
        for name, buffer in parts.items():
            buffer.dumps(tmp / name)
        write_manifest(tmp)
        if directory.exists():
            os.replace(directory, old)
        os.replace(tmp, directory)
    except (OSError, RuntimeError) as err:
        reason = _file_system_error(err)
        shutil.rmtree(tmp, ignore_errors=True)
        if reason is None:  # not the file system's doing: a bug, with its traceback
            raise
        raise CheckpointError(_write_failure(directory, reason)) from err
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _fsync_directory(directory.parent)
    shutil.rmtree(old, ignore_errors=True)
    return directory


def required_bytes(state_bytes: int, buffers: Iterable = ()) -> int:
    """The free space a checkpoint is allowed to start with: the state's size and every
    buffer's storage (all of its capacity: torchrl writes the whole storage), generously."""
    estimate = state_bytes + sum(_buffer_nbytes(buffer) for buffer in buffers)
    return int(estimate * SPACE_FACTOR) + SPACE_SLACK


def _buffer_nbytes(buffer) -> int:
    storage = getattr(buffer, "storage", buffer)
    data = getattr(storage, "_storage", None)
    if isinstance(data, torch.Tensor):
        nbytes = data.nbytes
    elif hasattr(data, "bytes"):  # a TensorDict: every stored tensor, nested ones included
        nbytes = int(data.bytes())
    else:
        nbytes = 0
    rows = getattr(storage, "max_size", 0)
    return nbytes + SAMPLER_BYTES_PER_ROW * (rows if isinstance(rows, int) else 0)


def _check_free_space(target: Path, needed: int) -> None:
    """Refuse before writing: on a full disk torchrl's memory-mapped writes end the process
    with SIGBUS, which no ``except`` can catch."""
    where = _existing_ancestor(target)
    free = shutil.disk_usage(where).free
    if free < needed:
        raise _NoSpace(
            f"{_mb(needed)} needed (the estimate with a margin), {_mb(free)} free on the "
            f"file system of {str(where)!r}"
        )


class _NoSpace(OSError):
    """Too little free space to start writing (the reason is the message)."""


# torch reports a failed file mapping (e.g. resizing a memmap file) as a RuntimeError naming
# the file in <...> and ending in the C library's ``strerror (errno)``.
_TORCH_FILE_ERROR = re.compile(
    r"^unable to .*?(<(?P<file>[^>]*)>.*)?: (?P<reason>[^:]+) \(\d+\)$", re.DOTALL
)


def _file_system_error(err: BaseException) -> str | None:
    """A one-line reason when ``err`` is the file system's (full, read-only, no permission),
    else None."""
    if isinstance(err, _NoSpace):
        return str(err)
    if isinstance(err, OSError):
        reason = err.strerror or type(err).__name__
        return f"{reason} ({err.filename!r})" if err.filename else reason
    match = _TORCH_FILE_ERROR.match(str(err).strip())
    if match is None:
        return None
    return f"{match['reason']} ({match['file']!r})" if match["file"] else match["reason"]


def _write_failure(directory: Path, reason: str) -> str:
    old = directory.with_name(directory.name + ".old")
    if not (directory / STATE_FILE).is_file() and (old / STATE_FILE).is_file():
        # Failed between the two renames: put the previous checkpoint back if possible.
        with contextlib.suppress(OSError):
            os.replace(old, directory)
    if (directory / STATE_FILE).is_file():
        previous = f"the previous checkpoint is intact in {str(directory)!r}"
    elif (old / STATE_FILE).is_file():
        previous = f"the previous checkpoint is intact in {str(old)!r}"
    else:
        previous = "there was no previous checkpoint"
    return f"Could not write the checkpoint {str(directory)!r}: {reason}; {previous}."


def check_writable(directory: str | Path) -> None:
    """Fail with a one-line :class:`CheckpointError` unless files can be created in
    ``directory`` (or, if it does not exist yet, in its nearest existing ancestor): a run
    should stop before it trains, not at its first checkpoint."""
    where = _existing_ancestor(Path(directory))
    try:
        handle, probe = tempfile.mkstemp(dir=where, prefix=".s3rl-write-test-")
        os.close(handle)
        os.unlink(probe)
    except OSError as err:
        raise CheckpointError(
            f"Cannot write in {str(where)!r} ({err.strerror or type(err).__name__}): a run "
            f"writes its checkpoints, metrics and config there; nothing was trained."
        ) from err


def _existing_ancestor(path: Path) -> Path:
    path = path.absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _mb(nbytes: int) -> str:
    return f"{nbytes / 1e6:,.1f} MB"


def write_manifest(directory: str | Path) -> Path:
    """Record the size and SHA-256 of every file under ``directory`` in ``manifest.json``
    (relative POSIX paths) and flush them to the disk: what :func:`verify_checkpoint` holds a
    checkpoint against. Written last, so a checkpoint with a manifest was written whole."""
    directory = Path(directory)
    files = {}
    for path in _files(directory):
        relative = path.relative_to(directory).as_posix()
        if relative == MANIFEST_FILE:
            continue
        files[relative] = {"size": path.stat().st_size, HASH: _digest(path, flush=True)}
    for folder in {directory, *(path.parent for path in _files(directory))}:
        _fsync_directory(folder)
    manifest = {"format": MANIFEST_FORMAT, "files": files}
    target = directory / MANIFEST_FILE
    with open(target, "w") as file:
        json.dump(manifest, file, indent=1, sort_keys=True)
        file.flush()
        os.fsync(file.fileno())
    _fsync_directory(directory)
    return target


def _files(directory: Path) -> list[Path]:
    return sorted(path for path in directory.rglob("*") if path.is_file())


def _digest(path: Path, flush: bool = False) -> str:
    """The file's SHA-256; ``flush``: also fsync it (the memory-mapped writes included), so a
    checkpoint that is swapped in is on the disk."""
    digest = hashlib.new(HASH)
    with open(path, "rb") as file:
        while chunk := file.read(HASH_CHUNK):
            digest.update(chunk)
        if flush:
            os.fsync(file.fileno())
    return digest.hexdigest()


def _fsync_directory(directory: Path) -> None:
    """Make the directory's entries (new files, renames) durable; best effort (not every
    platform or file system can open a directory)."""
    with contextlib.suppress(OSError):
        handle = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(handle)
        finally:
            os.close(handle)


def verify_checkpoint(directory: str | Path) -> bool:
    """Check every file of the checkpoint in ``directory`` against its manifest: none missing,
    none added, each with its recorded size and SHA-256. Raises a one-line
    :class:`CheckpointError` naming the first bad file. Returns False (with an
    :class:`UnverifiedCheckpointWarning`) for a checkpoint written before manifests, after
    checking the sizes of its buffer files."""
    directory = Path(directory)
    manifest_file = directory / MANIFEST_FILE
    if not manifest_file.is_file():
        _check_memmap_sizes(directory)
        warnings.warn(
            f"Checkpoint {str(directory)!r} has no {MANIFEST_FILE} (written before checkpoints "
            f"were verified): only its buffer files' sizes were checked. The next checkpoint "
            f"the run writes has one.",
            UnverifiedCheckpointWarning,
            stacklevel=2,
        )
        return False
    files = _read_manifest(manifest_file)
    for relative, entry in files.items():  # the cheap checks first: nothing is read yet
        path = directory / relative
        if not path.is_file():
            raise CheckpointError(
                f"Corrupt checkpoint: {str(path)!r} is missing (listed in {MANIFEST_FILE})."
            )
        size = path.stat().st_size
        if size != entry["size"]:
            raise CheckpointError(
                f"Corrupt checkpoint: {str(path)!r} has {size} bytes, {MANIFEST_FILE} "
                f"recorded {entry['size']} (truncated or overwritten)."
            )
    for path in _files(directory):
        relative = path.relative_to(directory).as_posix()
        if relative != MANIFEST_FILE and relative not in files:
            raise CheckpointError(
                f"Corrupt checkpoint: {str(path)!r} is not one of its files (not in "
                f"{MANIFEST_FILE}); remove it if it was put there on purpose."
            )
    for relative, entry in files.items():
        path = directory / relative
        if _digest(path) != entry[HASH]:
            raise CheckpointError(
                f"Corrupt checkpoint: {str(path)!r} does not match its {HASH} in "
                f"{MANIFEST_FILE} (its bytes changed after it was written)."
            )
    return True


def _read_manifest(manifest_file: Path) -> dict[str, dict[str, Any]]:
    try:
        manifest = json.loads(manifest_file.read_text())
        files = manifest["files"]
        if manifest["format"] != MANIFEST_FORMAT:
            raise ValueError(f"format {manifest['format']!r}, expected {MANIFEST_FORMAT!r}")
        for relative, entry in files.items():
            parts = Path(relative).parts
            if Path(relative).is_absolute() or ".." in parts or not parts:
                raise ValueError(f"the path {relative!r} is outside the checkpoint")
            if not isinstance(entry["size"], int) or not isinstance(entry[HASH], str):
                raise ValueError(f"the entry of {relative!r} is malformed")
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        detail = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise CheckpointError(
            f"Corrupt checkpoint: {str(manifest_file)!r} does not read ({detail})."
        ) from err
    return files


def _check_memmap_sizes(directory: Path) -> None:
    """What a checkpoint without a manifest allows: each buffer file (tensordict's
    ``<key>.memmap``) holds the bytes its ``meta.json`` shape and dtype imply. Only the
    buffers' storages are searched (``<buffer>/storage/``), never the whole directory: a
    ``state.pt`` may lie anywhere."""
    storages = sorted(d / "storage" for d in directory.iterdir() if (d / "storage").is_dir())
    meta_files = [meta for storage in storages for meta in sorted(storage.rglob("meta.json"))]
    for meta_file in meta_files:
        try:
            meta = json.loads(meta_file.read_text())
        except (OSError, ValueError) as err:
            raise CheckpointError(
                f"Corrupt checkpoint: {str(meta_file)!r} does not read ({type(err).__name__})."
            ) from err
        for key, entry in meta.items() if isinstance(meta, dict) else ():
            expected = _memmap_nbytes(entry)
            if expected is None:
                continue
            path = meta_file.parent / f"{key}.memmap"
            size = path.stat().st_size if path.is_file() else None
            if size != expected:
                found = "is missing" if size is None else f"has {size} bytes"
                raise CheckpointError(
                    f"Corrupt checkpoint: {str(path)!r} {found}, its meta.json's shape "
                    f"{entry['shape']} of {entry['dtype']} needs {expected}."
                )


def _memmap_nbytes(entry: Any) -> int | None:
    """The size of a dense tensor's memmap file per its meta.json entry; None when the entry
    is not one (a nested tensordict, a nested tensor, an empty tensor, an unknown dtype)."""
    if not isinstance(entry, dict) or entry.get("is_nested") or "shape" not in entry:
        return None
    dtype = getattr(torch, str(entry.get("dtype", "")).removeprefix("torch."), None)
    if not isinstance(dtype, torch.dtype):
        return None
    numel = 1
    for dim in entry["shape"]:
        numel *= int(dim)
    return numel * dtype.itemsize if numel else None


def resolve_checkpoint(path: str | Path) -> Path:
    """Accept a run directory, a checkpoint directory or a ``state.pt`` file."""
    path = Path(path).expanduser()
    directories = [
        path,
        path / "checkpoints" / "latest",
        path / "checkpoints" / "latest.old",  # a crash between the two renames
    ]
    candidates = [path, *(directory / STATE_FILE for directory in directories)]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    if path.name == STATE_FILE:
        directories.append(path.parent)
    for directory in directories:  # a checkpoint that lost its state file: verified as corrupt
        if (directory / MANIFEST_FILE).is_file():
            return directory / STATE_FILE
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
    """Load a checkpoint safely; returns the state and the checkpoint directory.

    Every file of the checkpoint (the buffers the caller loads later included) is verified
    against its manifest first (:func:`verify_checkpoint`): a corrupt checkpoint raises
    :class:`CheckpointError` before anything is built or trained."""
    file = resolve_checkpoint(path)
    # A file without a manifest is an old checkpoint only if it reads as one: its warning
    # ("written before checkpoints were verified") waits until then.
    with warnings.catch_warnings(record=True) as unverified:
        warnings.simplefilter("always", UnverifiedCheckpointWarning)
        verify_checkpoint(file.parent)
    try:
        state = torch.load(file, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        # Not torch's message: it advises weights_only=False, which would run the file's code.
        # torch raises this both for a class or function the file names (a "global") and for
        # bytes that are no pickle at all.
        if "global" in str(err):
            raise CheckpointError(
                f"{str(file)!r} is not a s3rl-torchrl checkpoint: it holds Python objects, "
                "where a checkpoint holds only tensors and containers (nothing of it was run)."
            ) from err
        raise CheckpointError(
            f"Checkpoint {str(file)!r} is corrupt or not a s3rl-torchrl checkpoint (it does not "
            "read as tensors and containers)."
        ) from err
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
    for warning in unverified:
        warnings.warn(warning.message, warning.category, stacklevel=2)
    return state, file.parent

