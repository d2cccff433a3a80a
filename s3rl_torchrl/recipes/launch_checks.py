"""What ``s3rl-train`` checks before Hydra writes anything or a launcher starts a job.

Hydra writes a job's ``.hydra/`` files and opens its log before the task function runs, and a
sweep's launcher starts its jobs one after the other. A bad value found by the task function
would therefore leave files behind (in the worst case in another run's directory: two commands
started into one directory), and a sweep with one bad job would stop after its valid jobs had
begun. :class:`LaunchChecks`, a Hydra callback (``hydra.callbacks`` in configs/train.yaml), runs
first:

- a single run (:meth:`LaunchChecks.on_run_start`): its config is validated, its run directory
  must be writable and, for a new run, hold no other run; the directory's lock is then taken
  (trainer/run_lock.py), which the trainer takes over;
- a sweep (:meth:`LaunchChecks.on_multirun_start`): every job's config is composed as the
  launcher will compose it and validated, and the bad ones are named together; no two jobs may
  train into one directory (a sweep over a key the directory's name leaves out, such as
  ``algo.lagrangian_target=0.5,0.7`` under the default ``<algo>_<task>_seed<N>``); the sweep's
  directory must be writable; ``hydra/launcher=slurm`` needs Slurm's ``sbatch``.

A command refused here prints one line per problem on stderr (``s3rl-train: ...``), writes
nothing and exits with status 2. A resume (``resume=<run dir>``) is checked by the recipe: its
config is the run's own, and it runs in ``<run>/resumes/<time>``.
"""

from __future__ import annotations

import copy
import shutil
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NamedTuple, NoReturn

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, open_dict, read_write

from s3rl_torchrl.recipes.unknown_options import describe_unknown_option
from s3rl_torchrl.trainer.run_lock import LOCK_FILE, RunInUseError, RunLock

__all__ = [
    "RUN_FILES", "LaunchChecks", "SweepJob", "job_problem", "sweep_jobs", "sweep_overrides",
]

# What a run writes at its directory's top level (trainer/loop.py, multiseed.py): a directory
# holding one of them holds a run.
RUN_FILES = ("metrics.csv", "config.json", "seeds.json", "checkpoints")
WRITABLE_RUN_DIR = "Give a directory you can write: hydra.run.dir=<dir>."
BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"
SLURM_LAUNCHER = "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"


def refuse(*lines: str) -> NoReturn:
    for line in lines:
        print(f"s3rl-train: {line}", file=sys.stderr)
    sys.exit(2)


def job_problem(config: DictConfig) -> str | None:
    """Why the recipe would refuse this job's config (a Hydra config, its ``hydra`` node
    included or not), or None. A resume of a given run is left to the recipe (its config is
    the run's own); ``resume=auto`` is checked as the new run it may start."""
    from s3rl_torchrl.trainer import ConfigError, validate

    resume = config.get("resume")
    if resume and resume != "auto":
        return None
    task_cfg = copy.deepcopy(config)
    with read_write(task_cfg), open_dict(task_cfg):
        task_cfg.pop("hydra", None)
        task_cfg.resume = None
    try:
        validate(task_cfg)
    except ConfigError as err:
        return str(err)
    return None


def _check_writable(
    directory: Path, advice: str, before_refusing: Callable[[], None] | None = None
) -> None:
    from s3rl_torchrl.trainer.checkpoint import CheckpointError, check_writable

    try:
        check_writable(directory)
    except CheckpointError as err:
        if before_refusing is not None:
            before_refusing()
        refuse(f"{err} {advice}")


class LaunchChecks(Callback):
    """``s3rl-train``'s checks before Hydra writes into a run directory or launches a sweep
    (the module's docstring says which)."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        problem = job_problem(config)
        if problem is not None:
            refuse(problem)
        resume = config.get("resume")
        if resume and resume != "auto":
            return
        run_dir = Path(str(config.hydra.run.dir))
        try:
            claim_run_dir(run_dir, config, continues=resume == "auto")
        except (RunInUseError, FileExistsError) as err:
            refuse(str(err))
        except OSError as err:  # the directory or its lock file cannot be made
            refuse(
                f"Cannot write in {str(err.filename or run_dir)!r} "
                f"({err.strerror or type(err).__name__}): a run writes its checkpoints, metrics "
                f"and config there; nothing was trained. {WRITABLE_RUN_DIR}"
            )
        # The lock file could be opened; files must be creatable too (a directory made
        # read-only since its run ended).
        _check_writable(run_dir, WRITABLE_RUN_DIR, lambda: RunLock.release_claim(run_dir))

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        jobs = sweep_jobs(config)
        if jobs is not None:
            bad = [job for job in jobs if job.problem is not None]
            if bad:
                refuse(
                    f"{len(bad)} of the sweep's {len(jobs)} jobs would be refused, so none was "
                    "started:",
                    *(f"  {_named(job)}: {job.problem}" for job in bad),
                )
            shared = _shared_run_dirs(jobs)
            if shared:
                refuse(
                    f"{sum(map(len, shared.values()))} of the sweep's {len(jobs)} jobs would "
                    "train into a directory another of them trains into, so none was started:",
                    *(f"  {run_dir}: {' | '.join(map(_named, group))}"
                      for run_dir, group in shared.items()),
                    "Name each job's directory by what the jobs differ in, e.g. "
                    "hydra.sweep.subdir='${hydra.job.override_dirname}', or by its number: "
                    "hydra.sweep.subdir='job${hydra.job.num}' (docs/recipes.md, \"Sweeps\").",
                )
        sweep_dir = Path(str(config.hydra.sweep.dir))
        _check_writable(sweep_dir, "Give a directory you can write: hydra.sweep.dir=<dir>.")
        launcher = str(config.hydra.launcher.get("_target_", ""))
        if launcher == SLURM_LAUNCHER and shutil.which("sbatch") is None:
            refuse(
                "hydra/launcher=slurm submits each job with Slurm's sbatch, which is not on "
                "this machine's PATH: run the sweep on the cluster's login node, or here with "
                "hydra/launcher=local_submitit or hydra/launcher=parallel (docs/recipes.md)."
            )


def claim_run_dir(run_dir: Path, config: DictConfig, continues: bool) -> RunLock:
    """Take ``run_dir``'s lock for the trainer to come; unless the command ``continues`` the
    run found there (``resume=auto``), refuse a directory that holds a run or another
    invocation's Hydra files. Nothing is written into a refused directory (not even the lock
    file's process id)."""

    def holds_no_other_run() -> None:
        if continues:
            return
        # A run's files, another command's .hydra/ or job log (train.log: Hydra names it after
        # the job).
        names = [*RUN_FILES, *filter(None, [config.hydra.output_subdir])]
        found = sorted(
            [name for name in names if (run_dir / name).exists()]
            + [log.name for log in run_dir.glob("*.log") if log.is_file()]
        )
        if found:
            raise FileExistsError(
                f"{run_dir} already holds a run ({', '.join(found)}); continue it with "
                f"resume={run_dir} or train into a new directory. Its files are untouched."
            )

    if not (run_dir / LOCK_FILE).exists():
        # Before the directory or its lock file is made. With a lock file, its owner (still
        # training?) is named first.
        holds_no_other_run()
    run_dir.mkdir(parents=True, exist_ok=True)
    return RunLock.claim(run_dir, check=holds_no_other_run)


class SweepJob(NamedTuple):
    """One job of a sweep, as the launcher will compose it."""

    overrides: list[str]
    problem: str | None  # why the recipe would refuse it, or None
    run_dir: Path | None  # where it would train; None where its config or directory does not resolve


def sweep_jobs(config: DictConfig) -> list[SweepJob] | None:
    """Every job of the sweep, as the basic sweeper splits it and the launcher composes it
    (the job's number set as the launcher sets it, so that its directory resolves). None for
    another sweeper (e.g. Optuna's, whose jobs are chosen as it goes)."""
    from hydra.core.global_hydra import GlobalHydra

    if str(config.hydra.sweeper.get("_target_", "")) != BASIC_SWEEPER:
        return None
    loader = GlobalHydra.instance().config_loader()
    params = config.hydra.sweeper.get("params") or {}
    arguments = [f"{key}={value}" for key, value in params.items()]
    arguments += list(config.hydra.overrides.task)
    jobs = []
    for num, overrides in enumerate(sweep_overrides(arguments, loader)):
        try:
            job_config = loader.load_sweep_config(config, list(overrides))
        except Exception as err:  # a value of the wrong type, an unknown key: Hydra's message
            problem = describe_unknown_option(err, "s3rl-train")
            jobs.append(SweepJob(list(overrides), problem or str(err).strip().splitlines()[0], None))
            continue
        jobs.append(SweepJob(list(overrides), job_problem(job_config), _job_dir(job_config, num)))
    return jobs


def _job_dir(job_config: DictConfig, num: int) -> Path | None:
    """Where the launcher runs job ``num`` (hydra/_internal/core_plugins/basic_launcher.py and
    the joblib launcher number their jobs in launch order), or None if that does not resolve
    before the job starts (a directory named by ``hydra.runtime.output_dir``, say)."""
    with read_write(job_config), open_dict(job_config):
        job_config.hydra.job.num = num
        job_config.hydra.job.id = str(num)
    try:
        return Path(str(job_config.hydra.sweep.dir)) / str(job_config.hydra.sweep.subdir)
    except Exception:  # an interpolation Hydra fills in only as the job starts
        return None


def _shared_run_dirs(jobs: list[SweepJob]) -> dict[Path, list[SweepJob]]:
    """The run directories that more than one job would train into, with those jobs."""
    by_dir: dict[Path, list[SweepJob]] = {}
    for job in jobs:
        if job.run_dir is not None:
            by_dir.setdefault(job.run_dir, []).append(job)
    return {run_dir: group for run_dir, group in by_dir.items() if len(group) > 1}


def _named(job: SweepJob) -> str:
    return " ".join(job.overrides) or "(no overrides)"


def sweep_overrides(arguments: Iterable[str], config_loader: Any = None) -> list[list[str]]:
    """Each job's overrides, as Hydra's basic sweeper expands ``arguments`` (``key=value``
    strings: a sweep's ``params`` then the command line's): one list per job, in launch order,
    the first key varying slowest. Hydra's own expansion, so that what a check or a queue
    (research/delivered_policy/evidence.py) reads is what ``--multirun`` launches."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create(config_loader=config_loader)
    batches = BasicSweeper.split_arguments(parser.parse_overrides(list(arguments)), None)
    return [list(job) for batch in batches for job in batch]
