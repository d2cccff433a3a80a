"""The Hydra recipes behind the console scripts ``s3rl-train`` and ``s3rl-eval``.

Their configs are the YAML files of the repository's top-level ``configs/``: a wheel ships that
directory inside the package as ``s3rl_torchrl/configs/`` (``pyproject.toml`` maps it), a source
checkout (editable install) reads it in place. :func:`config_dir` finds whichever is there.

Both recipes share two helpers around Hydra's output directory: :class:`HydraOutput` takes back
the directory Hydra made for a rejected command, and :func:`console_to_log` copies what a
command prints into Hydra's job log (``train.log``, ``evaluate.log``). What ``s3rl-train`` checks
before Hydra writes anything (its config, every job of a sweep, its run directory) is a Hydra
callback: :class:`s3rl_torchrl.recipes.launch_checks.LaunchChecks`.
"""

from __future__ import annotations

import functools
import logging
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from s3rl_torchrl.trainer.run_lock import LOCK_FILE, RunLock

CONFIG_NAMES = ("train.yaml", "evaluate.yaml")


def config_dir() -> Path:
    """The directory holding ``train.yaml`` and ``evaluate.yaml`` and the config groups."""
    package = Path(__file__).resolve().parents[1]
    candidates = (package / "configs", package.parent / "configs")  # wheel, source checkout
    for candidate in candidates:
        if all((candidate / name).is_file() for name in CONFIG_NAMES):
            return candidate
    raise FileNotFoundError(
        "The s3rl-torchrl configs are missing: looked for "
        + " and ".join(str(c) for c in candidates)
        + ". Reinstall the package (pip install s3rl-torchrl, or pip install -e . in a checkout)."
    )


# Warnings of third-party code that a user of the recipes cannot act on, each matched exactly
# (never all warnings). Their causes are not ours: tensordict reads a torch._dynamo option that
# torch deprecated; torchrl's SACLoss (and SACLagLoss, which evaluates its critics the same
# way) vmaps over locked parameter tensordicts, whose per-call copies tensordict locks, and
# warns about it, under torch.compile; Gymnasium's half_cheetah.xml (HalfCheetah-v4, the
# velocity task's robot) uses MuJoCo's deprecated settotalmass attribute.
TENSORDICT_DYNAMO_OPTION = r"torch\._dynamo\.config\.inline_inbuilt_nn_modules is deprecated"
TENSORDICT_COMPILED_LOCK = r"Using lock_\(\) inside a compiled graph"
MUJOCO_SETTOTALMASS = "compiler attribute 'settotalmass' is deprecated"


@functools.cache  # once per process: a second call would wrap MuJoCo's handler again
def quiet_known_warnings() -> None:
    """Silence exactly the third-party warnings above; every other warning is shown as before
    (MuJoCo's on stderr, with its ``WARNING:`` prefix).

    Warning filters and MuJoCo's handler belong to one process, so each recipe calls this in
    its Hydra task function: a launcher (joblib, submitit) runs that function in a process of
    its own. Calling it again in the same process changes nothing."""
    import mujoco

    warnings.filterwarnings(
        "ignore", message=TENSORDICT_DYNAMO_OPTION, category=FutureWarning, module="tensordict"
    )
    warnings.filterwarnings(
        "ignore", message=TENSORDICT_COMPILED_LOCK, category=UserWarning, module="tensordict"
    )
    previous = mujoco.get_mju_user_warning()

    def on_mujoco_warning(message: str) -> None:
        if message.startswith(MUJOCO_SETTOTALMASS):
            return
        if previous is not None:
            previous(message)
        else:
            print(f"WARNING: {message}", file=sys.stderr)

    mujoco.set_mju_user_warning(on_mujoco_warning)


# -------------------------------------------------------------------- Hydra's output directory
# When this process started to run the recipe (the recipe module imports this one before
# Hydra creates any directory): files modified since were written by this invocation. File
# timestamps come from a coarser clock than time.time(), hence the slack.
STARTED = time.time()
_TIMESTAMP_SLACK = 2.0
# What Hydra writes into a job's output directory before the task function runs: the job's
# log (train.log, evaluate.log) and these files in `hydra.output_subdir` (.hydra/); and
# s3rl-train's lock file (launch_checks.py).
HYDRA_CONFIG_FILES = frozenset({"config.yaml", "hydra.yaml", "overrides.yaml"})


def _written_by_this_invocation(path: Path) -> bool:
    return path.is_file() and path.stat().st_mtime >= STARTED - _TIMESTAMP_SLACK


@dataclass
class HydraOutput:
    """The job's output directory as the task function found it: what Hydra wrote there for
    this invocation, so that a rejected config can take it back (:meth:`remove_if_untouched`)."""

    dir: Path
    hydra_subdir: str | None  # `hydra.output_subdir` (".hydra"), None: not written
    log_files: dict[Path, bool]  # Hydra's job log in `dir` -> empty and new at the task's start
    cwd: Path  # where the command was started (`hydra.runtime.cwd`)

    @classmethod
    def current(cls) -> HydraOutput:
        """Call first thing in the task function (before anything logs to the job's log)."""
        from hydra.core.hydra_config import HydraConfig

        hydra_cfg = HydraConfig.get()
        out = Path(hydra_cfg.runtime.output_dir)
        logs = {}
        for handler in logging.getLogger().handlers:
            if isinstance(handler, logging.FileHandler):
                file = Path(handler.baseFilename)
                if file.parent == out:
                    logs[file] = _written_by_this_invocation(file) and file.stat().st_size == 0
        return cls(out, hydra_cfg.output_subdir, logs, Path(hydra_cfg.runtime.cwd))

    def untouched(self) -> bool:
        """True if the directory holds nothing but what Hydra wrote for this invocation: its
        ``.hydra/`` config files and its job log, created empty by this process."""
        if not self.dir.is_dir() or self.dir.resolve() in (self.cwd.resolve(), Path.home()):
            return False
        allowed = {file.name for file, fresh in self.log_files.items() if fresh}
        if _written_by_this_invocation(self.dir / LOCK_FILE):  # LaunchChecks', this command's
            allowed.add(LOCK_FILE)
        if self.hydra_subdir is not None:
            allowed.add(self.hydra_subdir)
            subdir = self.dir / self.hydra_subdir
            if subdir.exists():
                if not subdir.is_dir():
                    return False
                entries = list(subdir.iterdir())
                if not all(
                    p.name in HYDRA_CONFIG_FILES and _written_by_this_invocation(p)
                    for p in entries
                ):
                    return False
        return all(p.name in allowed for p in self.dir.iterdir())

    def remove_if_untouched(self) -> bool:
        """Remove the directory if :meth:`untouched`, then its parents left empty below the
        command's working directory (``outputs/<algo>/<task>/seed10/``); never a directory that
        holds anything else. True if removed."""
        if not self.untouched():
            return False
        root = logging.getLogger()
        for handler in list(root.handlers):
            if isinstance(handler, logging.FileHandler) and Path(handler.baseFilename) in (
                self.log_files
            ):
                root.removeHandler(handler)
                handler.close()
        for file in self.log_files:
            file.unlink(missing_ok=True)
        RunLock.release_claim(self.dir)
        (self.dir / LOCK_FILE).unlink(missing_ok=True)
        if self.hydra_subdir is not None and (self.dir / self.hydra_subdir).is_dir():
            for name in HYDRA_CONFIG_FILES:
                (self.dir / self.hydra_subdir / name).unlink(missing_ok=True)
            (self.dir / self.hydra_subdir).rmdir()
        self.dir.rmdir()
        cwd = self.cwd.resolve()
        parent = self.dir.resolve().parent
        while parent != cwd and cwd in parent.parents:
            try:
                parent.rmdir()  # only if empty
            except OSError:
                break
            parent = parent.parent
        return True


# ----------------------------------------------------------------- the console into the log
class _LinesToLog:
    """A stdout that writes through to the console and logs each complete line."""

    def __init__(self, stream, logger: logging.Logger):
        self._stream, self._logger, self._pending = stream, logger, ""

    def write(self, text: str) -> int:
        written = self._stream.write(text)
        *lines, self._pending = (self._pending + text).split("\n")
        for line in lines:
            if line.strip():
                self._logger.info(line.rstrip())
        return written

    def flush(self) -> None:
        self._stream.flush()

    def finish(self) -> None:
        if self._pending.strip():
            self._logger.info(self._pending.rstrip())
        self._pending = ""

    def __getattr__(self, name: str):  # encoding, isatty, fileno, ...
        return getattr(self._stream, name)


@contextmanager
def console_to_log(name: str) -> Iterator[logging.Logger]:
    """While open, what the recipe prints on stdout (the final table, the verdict, the run
    directory) also goes, line by line through Python logging, to Hydra's job log
    (``train.log``), and only there: the console shows it unchanged. Yields a logger that
    writes to that file only (e.g. for errors)."""
    files = [h for h in logging.getLogger().handlers if isinstance(h, logging.FileHandler)]
    logger = logging.getLogger(name)
    saved = (logger.handlers[:], logger.propagate, logger.level)
    logger.handlers = files or [logging.NullHandler()]
    logger.propagate = False
    logger.setLevel(logging.INFO)
    stdout = sys.stdout
    tee = _LinesToLog(stdout, logger)
    sys.stdout = tee
    try:
        yield logger
    finally:
        tee.finish()
        if sys.stdout is tee:
            sys.stdout = stdout
        logger.handlers, logger.propagate, logger.level = saved
