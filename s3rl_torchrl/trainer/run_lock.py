"""One training process per run directory.

Two processes training into one directory (a sweep with ``resume=auto`` launched twice, a run
resumed while it still trains) would append to the same ``metrics.csv`` and overwrite each
other's checkpoints without an error. A run holds an advisory lock (``flock``) on
``<run dir>/.s3rl-train.lock`` from before it writes anything until its loop ends; the
operating system releases it when the process dies, so a run killed with ``kill -9`` never
leaves a stale lock behind.

``s3rl-train`` takes the lock before Hydra writes its files into the run directory
(:class:`s3rl_torchrl.recipes.launch_checks.LaunchChecks`, :meth:`RunLock.claim`); the trainer
then continues with that lock (:meth:`RunLock.take`): ``flock`` refuses a second lock of one
file even to the process that holds the first.
"""

from __future__ import annotations

import fcntl
import os
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar

__all__ = ["LOCK_FILE", "RunInUseError", "RunLock"]

LOCK_FILE = ".s3rl-train.lock"


class RunInUseError(RuntimeError):
    """Another process is training into the run directory."""


class RunLock:
    """The exclusive lock of ``run_dir`` (which must exist), held until :meth:`release` or
    until the object is garbage collected. The lock file holds the owner's process id.

    ``check``, if given, runs once the lock is held and before the process id is written: an
    error it raises releases the lock and leaves the file as it was (e.g. the directory turns
    out to hold another run)."""

    # Locks taken before the trainer exists (claim()), until a trainer takes them over (take()).
    _claimed: ClassVar[dict[Path, RunLock]] = {}

    def __init__(self, run_dir: str | Path, check: Callable[[], None] | None = None) -> None:
        self.run_dir = Path(run_dir).resolve()
        fd = os.open(self.run_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise RunInUseError(
                f"{run_dir} is in use: another process (pid {owner}) is training into it; "
                "wait for it to end or stop it, or train into another directory. Its files are "
                "untouched."
            ) from None
        if check is not None:
            try:
                check()
            except BaseException:
                os.close(fd)
                raise
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._release = weakref.finalize(self, os.close, fd)

    @classmethod
    def claim(cls, run_dir: str | Path, check: Callable[[], None] | None = None) -> RunLock:
        """Lock ``run_dir`` for the trainer this process is about to build (:meth:`take`)."""
        lock = cls(run_dir, check)
        cls._claimed[lock.run_dir] = lock
        return lock

    @classmethod
    def take(cls, run_dir: str | Path) -> RunLock:
        """The lock of ``run_dir`` for a trainer: the one this process claimed, else a new one
        (so a second trainer into a directory is refused, in this process as in another)."""
        claimed = cls._claimed.pop(Path(run_dir).resolve(), None)
        return claimed if claimed is not None and claimed.held else cls(run_dir)

    @classmethod
    def release_claim(cls, run_dir: str | Path) -> None:
        """Release the lock this process claimed on ``run_dir`` (none: nothing to do)."""
        claimed = cls._claimed.pop(Path(run_dir).resolve(), None)
        if claimed is not None:
            claimed.release()

    @property
    def held(self) -> bool:
        return self._release.alive

    def release(self) -> None:
        """Let another process train into the directory (closing the file drops the lock)."""
        self._release()
