"""One training process per run directory.

Two processes training into one directory (a sweep with ``resume=auto`` launched twice, a run
resumed while it still trains) would append to the same ``metrics.csv`` and overwrite each
other's checkpoints without an error. A run holds an advisory lock (``flock``) on
``<run dir>/.s3rl-train.lock`` from before it writes anything until its loop ends; the
operating system releases it when the process dies, so a run killed with ``kill -9`` never
leaves a stale lock behind.
"""

from __future__ import annotations

import fcntl
import os
import weakref
from pathlib import Path

__all__ = ["LOCK_FILE", "RunInUseError", "RunLock"]

LOCK_FILE = ".s3rl-train.lock"


class RunInUseError(RuntimeError):
    """Another process is training into the run directory."""


class RunLock:
    """The exclusive lock of ``run_dir`` (which must exist), held until :meth:`release` or
    until the object is garbage collected. The lock file holds the owner's process id."""

    def __init__(self, run_dir: str | Path) -> None:
        path = Path(run_dir) / LOCK_FILE
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
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
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._release = weakref.finalize(self, os.close, fd)

    def release(self) -> None:
        """Let another process train into the directory (closing the file drops the lock)."""
        self._release()
