"""Checkpoints cannot be silently wrong: every file is verified against the manifest at load,
and a write that cannot finish (full disk, read-only directory) is a one-line
``CheckpointError`` that leaves the previous checkpoint loadable."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import stat
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import GatherStorage
from s3rl_torchrl.trainer import checkpoint as ckpt
from s3rl_torchrl.trainer.checkpoint import (
    MANIFEST_FILE,
    REPLAY_DIR,
    STATE_FILE,
    CheckpointError,
    UnverifiedCheckpointWarning,
    check_writable,
    load_checkpoint,
    save_checkpoint,
    verify_checkpoint,
)

OBS = "replay_buffer/storage/observation.memmap"
CAPACITY, STORED, OBS_DIM = 400, 300, 8


def make_buffer(storage_cls=GatherStorage, seed: int = 0) -> TensorDictReplayBuffer:
    generator = torch.Generator().manual_seed(seed)
    buffer = TensorDictReplayBuffer(storage=storage_cls(CAPACITY), batch_size=16)
    buffer.extend(
        TensorDict(
            {
                "observation": torch.randn(STORED, OBS_DIM, generator=generator),
                ("next", "cost"): torch.rand(STORED, 1, generator=generator),
                ("next", "done"): torch.zeros(STORED, 1, dtype=torch.bool),
            },
            [STORED],
        )
    )
    return buffer


def make_state(step: int = 1) -> dict:
    return {"counters": {"frames": 100 * step}, "weights": torch.full((4, 4), float(step))}


def saved(directory: Path, step: int = 1) -> Path:
    """A checkpoint of a 300-transition buffer (capacity 400) and a small state."""
    return save_checkpoint(directory, make_state(step), make_buffer(seed=step))


def one_line(err: pytest.ExceptionInfo) -> str:
    message = str(err.value)
    assert "\n" not in message
    return message


# ---------------------------------------------------------------------------- the manifest
@pytest.mark.parametrize("storage_cls", [GatherStorage, LazyTensorStorage])
def test_manifest_lists_every_file_and_the_checkpoint_round_trips(storage_cls, tmp_path):
    buffer = make_buffer(storage_cls)
    directory = save_checkpoint(tmp_path / "latest", make_state(), buffer)
    manifest = json.loads((directory / MANIFEST_FILE).read_text())
    assert manifest["format"] == ckpt.MANIFEST_FORMAT
    on_disk = {p.relative_to(directory).as_posix() for p in directory.rglob("*") if p.is_file()}
    on_disk.remove(MANIFEST_FILE)
    assert set(manifest["files"]) == on_disk and {STATE_FILE, OBS} <= on_disk
    for relative, entry in manifest["files"].items():
        data = (directory / relative).read_bytes()
        assert entry == {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    assert not (tmp_path / "latest.tmp").exists() and not (tmp_path / "latest.old").exists()

    assert verify_checkpoint(directory) is True
    state, loaded_dir = load_checkpoint(tmp_path / "latest")
    assert loaded_dir == directory and state["counters"] == {"frames": 100}
    restored = TensorDictReplayBuffer(storage=storage_cls(CAPACITY), batch_size=16)
    restored.loads(loaded_dir / REPLAY_DIR)
    assert len(restored) == STORED
    assert (restored[:].get("observation") == buffer[:].get("observation")).all()


def test_a_second_save_replaces_the_first_and_its_manifest(tmp_path):
    saved(tmp_path / "latest", step=1)
    directory = saved(tmp_path / "latest", step=2)
    state, _ = load_checkpoint(directory)
    assert state["counters"]["frames"] == 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest"]


# ---------------------------------------------------------------------------- corruption
def truncate(path: Path) -> None:
    with open(path, "r+b") as file:
        file.truncate(1000)


def flip_a_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


CORRUPTIONS = {
    # The issue's case: 1000 bytes left of the observations, the rest read back as zeros.
    "truncated memmap": (OBS, truncate, r"observation\.memmap' has 1000 bytes, .* recorded 12800"),
    "flipped byte": (OBS, flip_a_byte, r"observation\.memmap' does not match its sha256"),
    "deleted memmap": (OBS, os.remove, r"observation\.memmap' is missing"),
    "truncated state": (STATE_FILE, truncate, r"state\.pt' has 1000 bytes"),
    "deleted state": (STATE_FILE, os.remove, r"state\.pt' is missing"),
    "altered metadata": (
        "replay_buffer/storage/storage_metadata.json",
        lambda p: p.write_text(p.read_text().replace('"len": 300', '"len": 399')),
        r"storage_metadata\.json' does not match its sha256",
    ),
    "foreign file": (
        "replay_buffer/storage/reward.memmap",
        lambda p: p.write_bytes(b"\0" * 64),
        r"reward\.memmap' is not one of its files",
    ),
    "broken manifest": (
        MANIFEST_FILE,
        lambda p: p.write_text(p.read_text()[:50]),
        r"manifest\.json' does not read",
    ),
}


@pytest.mark.parametrize("case", sorted(CORRUPTIONS))
def test_a_corrupt_file_is_named_and_nothing_loads(case, tmp_path):
    relative, corrupt, message = CORRUPTIONS[case]
    directory = saved(tmp_path / "run" / "checkpoints" / "latest")
    corrupt(directory / relative)
    for path in (tmp_path / "run", directory, directory / STATE_FILE):  # each way to name it
        with pytest.raises(CheckpointError, match=message) as err:
            load_checkpoint(path)
        assert one_line(err).startswith("Corrupt checkpoint: ")


def test_the_issue_case_would_have_trained_on_zeros(tmp_path):
    # Why verification is needed: torchrl loads the truncated file without complaint and
    # reads zeros past its end.
    directory = saved(tmp_path / "latest")
    truncate(directory / OBS)
    buffer = TensorDictReplayBuffer(storage=GatherStorage(CAPACITY), batch_size=16)
    buffer.loads(directory / REPLAY_DIR)
    observations = buffer[:].get("observation")
    assert len(observations) == STORED and (observations[-1] == 0).all()
    with pytest.raises(CheckpointError, match="observation.memmap"):
        load_checkpoint(directory)


# ---------------------------------------------------------------------------- old checkpoints
def test_a_checkpoint_without_manifest_loads_with_a_warning(tmp_path):
    directory = saved(tmp_path / "latest")
    (directory / MANIFEST_FILE).unlink()  # as written before manifests
    with pytest.warns(UnverifiedCheckpointWarning, match="no manifest.json"):
        state, _ = load_checkpoint(directory)
    assert state["counters"]["frames"] == 100


def test_a_foreign_state_file_is_refused_without_torchs_advice(tmp_path):
    # Another program's torch.save (no manifest, a Python object inside): neither the
    # warning for old checkpoints nor torch's advice to load with weights_only=False, which
    # would run the file's code.
    import argparse
    import warnings

    torch.save({"args": argparse.Namespace(lr=1e-3)}, tmp_path / "state.pt")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(CheckpointError) as err:
            load_checkpoint(tmp_path / "state.pt")
    message = one_line(err)
    assert "is not a s3rl-torchrl checkpoint: it holds Python objects" in message
    assert "weights_only" not in message
    assert not [w for w in caught if issubclass(w.category, UnverifiedCheckpointWarning)]


def test_a_checkpoint_without_manifest_still_gets_its_buffer_sizes_checked(tmp_path):
    directory = saved(tmp_path / "latest")
    (directory / MANIFEST_FILE).unlink()
    truncate(directory / OBS)
    with pytest.raises(CheckpointError, match=r"observation\.memmap' has 1000 bytes.*12800"):
        load_checkpoint(directory)
    directory = saved(tmp_path / "other")
    (directory / MANIFEST_FILE).unlink()
    (directory / "replay_buffer/storage/next/cost.memmap").unlink()
    with pytest.raises(CheckpointError, match=r"cost\.memmap' is missing"):
        load_checkpoint(directory)


# ---------------------------------------------------------------------------- failed writes
def assert_previous_intact(directory: Path, step: int = 1) -> None:
    assert not directory.with_name(directory.name + ".tmp").exists()
    state, _ = load_checkpoint(directory)  # verified against its manifest
    assert state["counters"]["frames"] == 100 * step
    assert torch.equal(state["weights"], torch.full((4, 4), float(step)))


def fake_free_space(monkeypatch, free: int) -> None:
    real = shutil.disk_usage

    def disk_usage(path):
        return real(path)._replace(free=free)

    monkeypatch.setattr(shutil, "disk_usage", disk_usage)


def test_full_disk_is_refused_before_writing_and_keeps_the_previous(tmp_path, monkeypatch):
    directory = saved(tmp_path / "latest", step=1)
    fake_free_space(monkeypatch, 10 * 2**20)  # 10 MiB: less than the 32 MiB slack alone
    with pytest.raises(CheckpointError) as err:
        saved(directory, step=2)
    message = one_line(err)
    assert "MB needed" in message and "10.5 MB free" in message
    assert f"the previous checkpoint is intact in {str(directory)!r}" in message
    assert_previous_intact(directory, step=1)


def test_full_disk_without_a_previous_checkpoint_says_so(tmp_path, monkeypatch):
    fake_free_space(monkeypatch, 0)
    with pytest.raises(CheckpointError, match="there was no previous checkpoint"):
        saved(tmp_path / "checkpoints" / "latest")
    assert not (tmp_path / "checkpoints").exists()


def test_required_space_covers_the_whole_storage(tmp_path):
    buffer = make_buffer()
    storage_bytes = buffer.storage._storage.bytes()  # all 400 rows, as torchrl writes them
    needed = ckpt.required_bytes(1000, [buffer])
    assert needed >= 1.25 * (1000 + storage_bytes) + ckpt.SPACE_SLACK
    directory = save_checkpoint(tmp_path / "latest", make_state(), buffer)
    written = sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())
    assert written < needed - ckpt.SPACE_SLACK


def test_a_write_failing_inside_torchrl_keeps_the_previous(tmp_path):
    # A real failure of a memory-mapped write (torchrl resizing a memmap file past the file
    # size limit: torch's RuntimeError "unable to resize file ... (27)"), not a simulated one.
    resource = pytest.importorskip("resource")
    directory = saved(tmp_path / "latest", step=1)
    big = TensorDictReplayBuffer(storage=GatherStorage(20_000), batch_size=16)
    big.extend(TensorDict({"observation": torch.zeros(100, 64)}, [100]))  # 5 MB of storage
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, hard))
    try:
        with pytest.raises(CheckpointError) as err:
            save_checkpoint(directory, make_state(2), big)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    message = one_line(err)
    assert "File too large" in message and "previous checkpoint is intact" in message
    assert_previous_intact(directory, step=1)


def make_read_only(monkeypatch, directory: Path) -> None:
    """chmod a-w, or (as root, whom chmod does not stop) the error the file system would
    give: every directory created under ``directory`` fails with EROFS."""
    directory.chmod(stat.S_IRUSR | stat.S_IXUSR)
    probe = directory / "probe"
    try:
        probe.mkdir()
    except PermissionError:
        return
    probe.rmdir()
    directory.chmod(stat.S_IRWXU)
    real_mkdir = os.mkdir
    target = directory.absolute()

    def mkdir(path, *args, **kwargs):
        if Path(path).absolute().parent == target:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    real_mkstemp = ckpt.tempfile.mkstemp

    def mkstemp(*args, dir=None, **kwargs):
        if dir is not None and Path(dir).absolute() == target:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(dir))
        return real_mkstemp(*args, dir=dir, **kwargs)

    monkeypatch.setattr(ckpt.tempfile, "mkstemp", mkstemp)


def test_read_only_directory_is_a_clean_error(tmp_path, monkeypatch):
    checkpoints = tmp_path / "checkpoints"
    directory = saved(checkpoints / "latest", step=1)
    make_read_only(monkeypatch, checkpoints)
    try:
        with pytest.raises(CheckpointError) as err:
            saved(directory, step=2)
        message = one_line(err)
        assert "latest.tmp" in message and ("Read-only" in message or "Permission" in message)
        assert f"the previous checkpoint is intact in {str(directory)!r}" in message
        with pytest.raises(CheckpointError, match="Cannot write in .*nothing was trained"):
            check_writable(checkpoints)
        with pytest.raises(CheckpointError, match=str(checkpoints)):
            check_writable(checkpoints / "not" / "yet")  # its nearest existing ancestor
    finally:
        checkpoints.chmod(stat.S_IRWXU)
    assert_previous_intact(directory, step=1)
    check_writable(tmp_path / "new_run")


def test_failure_between_the_two_renames_puts_the_previous_back(tmp_path, monkeypatch):
    directory = saved(tmp_path / "latest", step=1)
    real_replace = os.replace

    def replace(src, dst):
        if Path(src).name == "latest.tmp":
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(src))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(CheckpointError, match="previous checkpoint is intact in '.*latest'"):
        saved(directory, step=2)
    monkeypatch.undo()
    assert not (tmp_path / "latest.old").exists()
    assert_previous_intact(directory, step=1)


def test_a_bug_while_writing_keeps_its_traceback_and_the_previous(tmp_path):
    directory = saved(tmp_path / "latest", step=1)

    class Broken:
        def dumps(self, path):
            Path(path).mkdir()
            raise ValueError("a bug, not the disk")

    with pytest.raises(ValueError, match="a bug"):
        save_checkpoint(directory, make_state(2), buffers={"broken": Broken()})
    assert_previous_intact(directory, step=1)


# ---------------------------------------------------------------------------- through the trainer
@pytest.mark.slow
def test_resuming_a_truncated_buffer_fails_before_anything_trains(tiny_config, tmp_path):
    from s3rl_torchrl.trainer import train

    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    latest = tmp_path / "checkpoints" / "latest"
    truncate(latest / OBS)  # the issue's reproduction
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    resumed = tiny_config("algo=sac", "collector.total_frames=400")
    resumed.resume = str(tmp_path)
    with pytest.raises(CheckpointError, match=r"observation\.memmap' has 1000 bytes") as err:
        train(resumed, tmp_path / "ignored")
    one_line(err)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
    assert not (tmp_path / "ignored").exists()


@pytest.mark.slow
def test_a_full_disk_mid_run_stops_cleanly_and_the_run_resumes(tiny_config, tmp_path, monkeypatch):
    from s3rl_torchrl.trainer import train

    latest = tmp_path / "checkpoints" / "latest"
    real = shutil.disk_usage

    def disk_usage(path):  # the disk fills up once the first checkpoint is written
        usage = real(path)
        return usage._replace(free=0) if latest.exists() else usage

    monkeypatch.setattr(shutil, "disk_usage", disk_usage)
    cfg = tiny_config("algo=sac", "collector.total_frames=400")
    with pytest.raises(CheckpointError, match="previous checkpoint is intact in") as err:
        train(cfg, tmp_path)
    one_line(err)
    assert not list(tmp_path.glob("checkpoints/*.tmp"))
    state, _ = load_checkpoint(tmp_path)
    assert state["counters"]["frames"] == 200

    monkeypatch.undo()  # space freed: the run continues from its last checkpoint
    cfg.resume = str(tmp_path)
    result = train(cfg, tmp_path / "ignored")
    assert result.status == "finished" and result.counters.frames == 400
