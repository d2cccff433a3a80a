"""Find training runs below a directory and group them by task and algorithm.

A run is a directory holding ``config.json`` and ``metrics.csv`` (what ``s3rl-train`` writes,
whether as a single run, a Hydra multirun job or one seed of a multi-seed group). It is
*finished* when its ``final_eval.json`` exists: only finished runs enter the final tables,
every run enters the learning curves.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import math
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from omegaconf.errors import OmegaConfBaseException

__all__ = [
    "PROTOCOLS",
    "Export",
    "ReportError",
    "Run",
    "RunGroup",
    "find_runs",
    "read_run",
    "group_runs",
    "flatten",
    "config_differences",
    "under_protocol",
    "picked_candidate",
    "runs_by_key",
    "late_epochs",
    "LATE_SHARE",
    "final_evaluation",
    "RUN_SPECIFIC_KEYS",
]

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.csv"
FINAL_EVAL_FILE = "final_eval.json"
CHECKPOINT_DIR = Path("checkpoints") / "latest"
# Figure 4's panel of a run, stored beside an exported copy (report.embeddings.save_panel).
FIGURE4_FILES = ("figure4_states.csv", "figure4_probe.json")

#: Config keys that may differ between the seeds of one group: they do not change what is
#: learned (how a run is logged, resumed, threaded or compiled), or are the seed itself.
RUN_SPECIFIC_KEYS = (
    "seed",
    "resume",
    "logger",
    "threads",
    "compile",
    "device",
    "save_interval",
    "eval.random_baseline",
    "resumes",  # what each resume changed (trainer.resume.record_resume)
    "objective",  # what the run returns to a sweeper
)


class ReportError(ValueError):
    """The runs cannot be reported as asked (nothing found, mixed configs, ...)."""


@dataclass
class Run:
    """One run directory, read."""

    path: Path
    config: dict[str, Any]
    metrics: list[dict[str, float]]  # metrics.csv rows, values as floats (NaN if empty)
    final: dict[str, Any] | None  # final_eval.json, None while unfinished

    @property
    def task(self) -> str:
        return self.config["task"]["name"]

    @property
    def algo(self) -> str:
        return self.config["algo"]["name"]

    @property
    def seed(self) -> int:
        return int(self.config["seed"])

    @property
    def cost_limit(self) -> float:
        return float(self.config["task"].get("cost_limit", math.nan))

    @property
    def finished(self) -> bool:
        return self.final is not None

    @property
    def frames(self) -> int:
        """Frames reached (the last metrics row), 0 before the first epoch."""
        return int(self.metrics[-1]["frames"]) if self.metrics else 0

    @property
    def total_frames(self) -> int:
        return int(self.config["collector"]["total_frames"])

    @property
    def checkpoint(self) -> Path | None:
        path = self.path / CHECKPOINT_DIR
        return path if path.is_dir() else None

    @cached_property
    def settings(self) -> dict[str, Any]:
        """The config the run ran with, flattened (``algo.pid.kp``), as this version reads it
        (``trainer.config.saved_config_node``): an option added after the run holds the
        default the run had, a field its algorithm family never read is gone. So a run saved
        before ``algo.cost_target_read`` existed and one saved with it unset are the same
        experiment. A config this version cannot read (an option removed at a value other than
        its default) is compared as written."""
        # The trainer's config pulls in torch through the algorithms: imported only once a
        # report compares configs.
        from s3rl_torchrl.trainer.config import saved_train_config, to_container

        written = {key: value for key, value in self.config.items() if key != "resumes"}
        try:
            return flatten(to_container(saved_train_config(written)))
        except (ValueError, OmegaConfBaseException):  # ConfigError is a ValueError
            return flatten(written)

    def late_mean(self, name: str) -> float:
        """The mean of a metrics.csv column over the last 20% of epochs (:func:`late_epochs` of
        the rows), its empty cells and NaN skipped; NaN when none holds a number. Of
        ``train/cost``, the cost the multiplier held at the end of training."""
        values = [v for v in late_epochs([r.get(name, math.nan) for r in self.metrics])
                  if not math.isnan(v)]
        return sum(values) / len(values) if values else math.nan

    def column(self, name: str) -> tuple[list[float], list[float]]:
        """(frames, values) of a metrics.csv column where it holds a number: rows without the
        column, its empty cells and NaN (e.g. the probe before both classes exist) are skipped."""
        rows = [r for r in self.metrics if not math.isnan(r.get(name, math.nan))]
        return [r["frames"] for r in rows], [r[name] for r in rows]


@dataclass
class RunGroup:
    """The seeds of one (task, algo[, --group-by values]) configuration."""

    task: str
    algo: str
    runs: list[Run]
    extra: tuple[tuple[str, Any], ...] = ()  # the --group-by keys and their values
    cost_limit: float = field(init=False)

    def __post_init__(self) -> None:
        self.runs = sorted(self.runs, key=lambda r: r.seed)
        self.cost_limit = self.runs[0].cost_limit

    @property
    def label(self) -> str:
        """The algo, plus the --group-by values that set this group apart."""
        if not self.extra:
            return self.algo
        return self.algo + " (" + ", ".join(f"{k}={v}" for k, v in self.extra) + ")"

    @property
    def finished(self) -> list[Run]:
        return [r for r in self.runs if r.finished]

    @property
    def unfinished(self) -> list[Run]:
        return [r for r in self.runs if not r.finished]


#: How a run's final evaluation was taken (``final_eval.json``): the policy at the end of
#: training (the top level), the best-feasible checkpoint FSRL's trainer keeps
#: (``best_feasible``, trainer.evaluation.BestFeasible), which may be how the paper's Table 1
#: was made, or the policy picked among the last epochs' (``delivered``, eval.delivery_epochs).
PROTOCOLS = {
    "last": "last policy",
    "best_feasible": "best-feasible checkpoint (FSRL's rule)",
    # eval.delivery_epochs: picked among the last epochs' policies on episodes of its own.
    "delivered": "delivered policy (picked among the last epochs')",
}


def under_protocol(group: RunGroup, protocol: str) -> RunGroup | None:
    """``group`` with each finished run's final evaluation read under ``protocol``; None when
    no run of it has that evaluation (runs written before the best-feasible checkpoint)."""
    if protocol == "last":
        return group
    runs = [
        dataclasses.replace(run, final=run.final[protocol])
        for run in group.finished
        if protocol in run.final
    ]
    return RunGroup(group.task, group.algo, runs, group.extra) if runs else None


#: The share of a run's epochs its late-training statistics read (the last 20%: what the
#: multiplier held at the end, research/2026-11-24-lambda-cadence.md).
LATE_SHARE = 0.2


def late_epochs(rows: Sequence[Any], share: float = LATE_SHARE) -> Sequence[Any]:
    """The last ``share`` of ``rows`` (one per epoch, in order), at least one."""
    return rows[-max(1, round(share * len(rows))):]


def runs_by_key(roots: Sequence[str | Path]) -> dict[tuple[str, str, int], Run]:
    """(task, algo, seed) -> the run, over every run below ``roots`` (one preset's result
    trees); a key found twice is an error, since a comparison would have to guess which."""
    runs: dict[tuple[str, str, int], Run] = {}
    for root in roots:
        for run in find_runs(root):
            key = (run.task, run.algo, run.seed)
            if key in runs:
                raise ReportError(
                    f"{run.task} {run.algo} seed {run.seed} is in {runs[key].path} and in "
                    f"{run.path}: give each preset's runs once."
                )
            runs[key] = run
    return runs


def picked_candidate(delivered: dict) -> dict | None:
    """The candidate entry of the policy ``final_eval.json``'s ``delivered`` record picked (its
    epoch and its reward and cost on the picking episodes), None when the record lists none."""
    return next((c for c in delivered.get("candidates", []) if c["epoch"] == delivered["epoch"]),
                None)


def final_evaluation(run: Run, protocol: str) -> dict | None:
    """``run``'s final evaluation under ``protocol`` (a PROTOCOLS key), None when it has none
    (unfinished, or written before that protocol existed). Under ``delivered``, a run without
    ``eval.delivery_epochs`` picked nothing: it delivered its last policy, which is what a
    preset before the pick is compared on."""
    if run.final is None:
        return None
    if protocol == "delivered" and not run.config.get("eval", {}).get("delivery_epochs"):
        return run.final
    return run.final if protocol == "last" else run.final.get(protocol)


def _read_metrics(path: Path) -> list[dict[str, float]]:
    with path.open(newline="") as f:
        rows = [
            {k: float(v) if v not in ("", None) else math.nan for k, v in row.items()}
            for row in csv.DictReader(f)
        ]
    for row in rows:
        _add_cost_share(row)
    return rows


GRADIENT_TERMS = ("grad/reward", "grad/entropy", "grad/cost")


def _add_cost_share(row: dict[str, float]) -> None:
    """``grad/cost_share``: the cost term's part of the actor's gradient norms (the critic
    diagnostics' ``grad/*`` columns), NaN where a term is missing or all are 0."""
    if not all(name in row for name in GRADIENT_TERMS):
        return
    norms = [row[name] for name in GRADIENT_TERMS]
    total = sum(norms)
    row["grad/cost_share"] = norms[2] / total if total > 0 else math.nan


def read_run(path: str | Path) -> Run:
    path = Path(path)
    try:
        config = json.loads((path / CONFIG_FILE).read_text())
        final_path = path / FINAL_EVAL_FILE
        final = json.loads(final_path.read_text()) if final_path.is_file() else None
        metrics = _read_metrics(path / METRICS_FILE)
    except (OSError, ValueError) as err:
        raise ReportError(f"Cannot read the run in {path}: {err}") from err
    for key in ("task", "algo", "seed", "collector"):
        if key not in config:
            raise ReportError(
                f"{path / CONFIG_FILE} has no {key!r} entry: not a config written by s3rl-train."
            )
    return Run(path, config, metrics, final)


def find_runs(root: str | Path) -> list[Run]:
    """Every run directory at or below ``root`` (sorted by path); an error if there is none."""
    root = Path(root)
    if not root.is_dir():
        raise ReportError(f"{root} is not a directory.")
    run_dirs = sorted(
        p.parent
        for p in root.rglob(CONFIG_FILE)
        if (p.parent / METRICS_FILE).is_file() and "checkpoints" not in p.relative_to(root).parts
    )
    if not run_dirs:
        raise ReportError(
            f"No runs found below {root}: a run is a directory with {CONFIG_FILE} and "
            f"{METRICS_FILE}, as s3rl-train writes them (outputs/ or multirun/ by default)."
        )
    return [read_run(p) for p in run_dirs]


# What a run's results are: small text files. Checkpoints and replay buffers stay behind.
EXPORTED_FILES = (CONFIG_FILE, METRICS_FILE, FINAL_EVAL_FILE, *FIGURE4_FILES)


@dataclass
class Export:
    copied: list[Path]  # the run copies below DEST, one per run below ROOT
    removed: list[Path]  # copies of runs no longer below ROOT, removed from DEST


def export_runs(root: str | Path, dest: str | Path) -> Export:
    """Copy the results of every run below ``root`` (``config.json``, ``metrics.csv`` and, once
    finished, ``final_eval.json``; a Figure-4 panel if the run has one) to the same relative
    place below ``dest``, so that a report can be rebuilt from a small tree kept in version
    control (``s3rl-report DEST``). ``dest`` then mirrors the runs: a file an earlier export
    left in a run's copy that the run no longer has is removed, and so is the copy of a run that
    is gone from ``root`` (its exported files, and its directory once empty).
    ``report.build.export_embedding_panels`` adds the panels drawn from the checkpoints."""
    root, dest = Path(root), Path(dest)
    runs = find_runs(root)
    if dest.resolve().is_relative_to(root.resolve()) or root.resolve().is_relative_to(
        dest.resolve()
    ):
        raise ReportError(f"--export-runs {dest} must lie outside {root} (and not contain it).")
    copied = []
    for run in runs:
        target = dest / run.path.relative_to(root)
        target.mkdir(parents=True, exist_ok=True)
        for name in EXPORTED_FILES:
            if (run.path / name).is_file():
                shutil.copyfile(run.path / name, target / name)
            elif name not in FIGURE4_FILES:
                # e.g. the final_eval.json of an earlier export of a run now re-run: the copy
                # must say what the run says. Panels stay: export_embedding_panels owns them.
                (target / name).unlink(missing_ok=True)
        copied.append(target)
    kept = {path.resolve() for path in copied}
    removed = []
    for config in sorted(dest.rglob(CONFIG_FILE)):
        stale = config.parent
        if stale.resolve() in kept or not (stale / METRICS_FILE).is_file():
            continue
        for name in EXPORTED_FILES:
            (stale / name).unlink(missing_ok=True)
        with contextlib.suppress(OSError):  # other files of the user's stay, and their folder
            stale.rmdir()
        removed.append(stale)
    return Export(copied, removed)


def flatten(config: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}`` (lists stay values)."""
    out: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, name + "."))
        else:
            out[name] = value
    return out


def _ignored(key: str, ignore: Iterable[str]) -> bool:
    return any(key == k or key.startswith(k + ".") for k in ignore)


def config_differences(
    runs: Sequence[Run], ignore: Iterable[str] = RUN_SPECIFIC_KEYS
) -> dict[str, list[Any]]:
    """The config keys whose values differ between ``runs`` -> each run's value (in order),
    read as each run ran (:attr:`Run.settings`)."""
    ignore = tuple(ignore)
    flats = [r.settings for r in runs]
    keys = sorted(set().union(*flats))
    missing = object()
    diff = {}
    for key in keys:
        if _ignored(key, ignore):
            continue
        values = [f.get(key, missing) for f in flats]
        if any(v != values[0] for v in values[1:]):
            diff[key] = ["<missing>" if v is missing else v for v in values]
    return diff


def group_runs(runs: Sequence[Run], group_by: Sequence[str] = ()) -> list[RunGroup]:
    """Group runs by task, algo and the ``group_by`` config keys (dotted, e.g. ``algo.pid.kp``).

    Raises :class:`ReportError` when the runs of a group differ in a config key other than the
    run-specific ones (:data:`RUN_SPECIFIC_KEYS`), naming the keys so they can be passed as
    ``group_by``, or when one seed appears twice in a group.
    """
    buckets: dict[tuple, list[Run]] = {}
    for run in runs:
        flat = run.settings
        for key in group_by:
            if key not in flat:
                raise ReportError(
                    f"--group-by {key!r}: no such config key in {run.path / CONFIG_FILE}."
                )
        extra = tuple((key, flat[key]) for key in group_by)
        buckets.setdefault((run.task, run.algo, extra), []).append(run)

    groups = []
    for (task, algo, extra), members in sorted(buckets.items(), key=lambda kv: str(kv[0])):
        diff = config_differences(members, (*RUN_SPECIFIC_KEYS, *group_by))
        if diff:
            lines = "\n".join(
                f"  {key}: "
                + ", ".join(f"{v!r} ({r.path})" for v, r in zip(values, members))
                for key, values in diff.items()
            )
            raise ReportError(
                f"The runs of task={task} algo={algo} differ in more than the seed, so they are "
                f"not seeds of one experiment:\n{lines}\nReport them separately (point "
                f"s3rl-report at a narrower directory) or split them with "
                + " ".join(f"--group-by {key}" for key in diff) + "."
            )
        seeds: dict[int, Run] = {}
        for run in members:
            if run.seed in seeds:
                raise ReportError(
                    f"Seed {run.seed} of task={task} algo={algo} appears twice: "
                    f"{seeds[run.seed].path} and {run.path}. Keep one of them below the "
                    "reported directory."
                )
            seeds[run.seed] = run
        groups.append(RunGroup(task, algo, members, extra))
    return groups
