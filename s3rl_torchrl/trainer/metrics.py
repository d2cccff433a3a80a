"""Run metrics: torchrl's loggers plus one ``metrics.csv`` table per run (one row per epoch).

On resume both continue from the checkpoint's frame count: what the interrupted run appended
after that checkpoint is cut off first, so the files have neither gaps nor duplicates. A
checkpoint records the size of every file the run appends to (:func:`appended_files`); a
resume cuts each back to that size and removes the ones created since
(:func:`cut_back_to_checkpoint`). A checkpoint written before that record drops the rows whose
step is past its frame count instead.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Any

import torch
from torchrl.record.loggers import Logger
from torchrl.record.loggers.csv import CSVLogger

METRICS_FILE = "metrics.csv"
STEP_COLUMN = "frames"
LOG_DIR = "logs"  # the torchrl logger's files, inside the run directory
# The run's other files at its top level: the config it runs with (and its resumes), and the
# final evaluation.
CONFIG_FILE = "config.json"
FINAL_EVAL_FILE = "final_eval.json"


def make_torchrl_logger(
    backend: str, run_dir: Path, exp_name: str, project: str, wandb_mode: str
) -> Logger | None:
    """One of torchrl's loggers, writing inside the run directory (no server needed)."""
    log_dir = run_dir / LOG_DIR
    if backend == "none":
        return None
    if backend == "csv":
        return Mp4CSVLogger(exp_name=exp_name, log_dir=str(log_dir))
    if backend == "tensorboard":
        from torchrl.record.loggers.tensorboard import TensorboardLogger

        return TensorboardLogger(exp_name=exp_name, log_dir=str(log_dir))
    if backend == "wandb":
        from torchrl.record.loggers.wandb import WandbLogger

        return WandbLogger(
            exp_name=exp_name,
            offline=wandb_mode == "offline",
            save_dir=str(log_dir),
            project=project,
            mode=wandb_mode,
        )
    if backend == "mlflow":
        from torchrl.record.loggers.mlflow import MLFlowLogger

        # A file store in the run directory: no server, no database package. MLflow 3 keeps it
        # behind an opt-in ("maintenance mode") that we take unless the user decided otherwise.
        os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        return MLFlowLogger(exp_name=exp_name, tracking_uri=(log_dir / "mlruns").resolve().as_uri())
    raise ValueError(
        f"Unknown logger backend {backend!r}; valid are csv, tensorboard, wandb, mlflow, none."
    )


class Mp4CSVLogger(CSVLogger):
    """torchrl's CSV logger whose videos are playable mp4 files,
    ``logs/<exp>/videos/<tag>_<step>.mp4`` (the training video, ``eval.video_interval``).

    torchrl's own CSV videos are tensor files (``.pt``) by default, and its mp4 writer needs
    torchcodec and a system FFmpeg; this one writes with imageio-ffmpeg (a dependency, its
    FFmpeg bundled). Scalars are torchrl's, unchanged."""

    def log_video(self, name: str, video: torch.Tensor, step: int | None = None, **kwargs) -> None:
        from s3rl_torchrl.envs.video import VideoWriter

        if video.dim() != 5 or video.size(2) not in (1, 3):
            raise ValueError(f"log_video takes a [N, T, C, H, W] video, got {tuple(video.shape)}.")
        if step is None:
            step = self.experiment.videos_counter[name]
            self.experiment.videos_counter[name] += 1
        frames = video.reshape(-1, *video.shape[-3:]).expand(-1, 3, -1, -1).permute(0, 2, 3, 1)
        path = Path(self.experiment.log_dir, "videos", f"{name}_{step}.mp4")
        with VideoWriter(path, fps=kwargs.get("fps", self.video_fps)) as writer:
            for frame in frames.to(torch.uint8).cpu().numpy():
                writer.append(frame)



def _appended_by_the_run(relative: Path) -> bool:
    """Whether the run only ever appends to this file (a path relative to the run directory):
    ``metrics.csv``, and what the loggers append to in ``logs/``: the CSV logger's scalar files
    (``scalars/<name>.csv``, ``scalars/lagrangian/value.csv``, ...), TensorBoard's event files,
    MLflow's metric files. Not W&B's: its service process writes them in the background, so
    their size at a checkpoint is no record boundary (a resumed run starts a new offline run);
    not MLflow's ``meta.yaml`` nor the Hydra job log, which are rewritten or record the
    invocation rather than the run."""
    parts = relative.parts
    if parts == (METRICS_FILE,):
        return True
    if not parts or parts[0] != LOG_DIR or "wandb" in parts:
        return False
    if relative.suffix == ".csv" or relative.name.startswith("events.out.tfevents."):
        return True
    return "mlruns" in parts and "metrics" in parts[parts.index("mlruns") :]


def appended_files(run_dir: str | Path) -> dict[str, int]:
    """The size of every file the run appends to (:func:`_appended_by_the_run`), by path
    relative to the run directory: what a checkpoint records so that a resume can cut the files
    back to it. Call it after the loggers have flushed."""
    run_dir = Path(run_dir)
    return {
        path.relative_to(run_dir).as_posix(): path.stat().st_size for path in _appended(run_dir)
    }


def _appended(run_dir: Path) -> list[Path]:
    candidates = [run_dir / METRICS_FILE, *(run_dir / LOG_DIR).rglob("*")]
    return sorted(
        path
        for path in candidates
        if path.is_file() and _appended_by_the_run(path.relative_to(run_dir))
    )


def cut_back_to_checkpoint(
    run_dir: str | Path, recorded: dict[str, int] | None, frames: int
) -> None:
    """Undo what an interrupted run appended after its last checkpoint, before a resume logs
    anything: each file the checkpoint ``recorded`` (:func:`appended_files`) is cut back to its
    recorded size, and a file the run appends to that did not exist then is removed. Without a
    record (a checkpoint written before it), the rows of ``metrics.csv`` and of the CSV logger's
    scalar files (at any depth) whose step is past ``frames`` are dropped."""
    run_dir = Path(run_dir)
    if recorded is None:
        if (run_dir / METRICS_FILE).is_file():
            _trim_csv(run_dir / METRICS_FILE, frames, header=True)
        for file in sorted((run_dir / LOG_DIR).glob("*/scalars/**/*.csv")):
            _trim_csv(file, frames, header=False)
        return
    for path in _appended(run_dir):
        size = recorded.get(path.relative_to(run_dir).as_posix())
        if size is None:
            path.unlink()
        elif path.stat().st_size > size:
            os.truncate(path, size)


def _trim_csv(path: Path, max_step: int, header: bool) -> None:
    """Drop rows whose step (the ``frames`` column; the first of a headerless scalar file) is
    beyond ``max_step`` (written after the last checkpoint)."""
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    head, body = (rows[:1], rows[1:]) if header else ([], rows)
    step_index = head[0].index(STEP_COLUMN) if head else 0
    kept = [r for r in body if r and float(r[step_index]) <= max_step]
    if len(kept) != len(body):
        # The line ends each file was written with: csv's for metrics.csv, "\n" for the
        # CSV logger's.
        with path.open("w", newline="") as f:
            csv.writer(f, lineterminator="\r\n" if header else "\n").writerows(head + kept)


def ensure_new_run_dir(run_dir: str | Path) -> None:
    """Refuse to start a new run where one already wrote its metrics (its files stay intact)."""
    if (Path(run_dir) / METRICS_FILE).exists():
        raise FileExistsError(
            f"{run_dir} already holds a run ({METRICS_FILE}); continue it with "
            f"resume={run_dir} or train into a new directory."
        )


class RunMetrics:
    """Writes epoch rows to ``metrics.csv`` and every scalar to a torchrl logger. A resumed run
    continues the files as :func:`cut_back_to_checkpoint` left them."""

    def __init__(self, run_dir: Path, logger: Logger | None, resume: bool = False):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / METRICS_FILE
        self.logger = logger
        self.columns: list[str] | None = None
        if not resume:
            ensure_new_run_dir(run_dir)
        if self.path.exists():
            with self.path.open(newline="") as f:
                self.columns = next(csv.reader(f), None)

    def appended_files(self) -> dict[str, int]:
        """What a checkpoint records (:func:`appended_files`), once the logger has written
        what it buffers (TensorBoard's writer holds events back)."""
        if self.logger is not None:
            self.logger.flush()  # torchrl's: the experiment's own flush, where it has one
        return appended_files(self.run_dir)

    def close(self) -> None:
        """End the logger's run. W&B and MLflow keep one active run per process: a run left open
        would take the next training's scalars in the same process (a -m sweep under Hydra's
        basic launcher runs its jobs one after another), or refuse it (MLflow)."""
        if self.logger is None:
            return
        from torchrl.record.loggers.mlflow import MLFlowLogger

        self.logger.close()  # torchrl's: flush, then W&B's finish or TensorBoard's close
        if isinstance(self.logger, MLFlowLogger):
            import mlflow

            mlflow.end_run()  # torchrl's close leaves MLflow's active run open
        self.logger = None

    def log_scalars(self, values: dict[str, float], step: int) -> None:
        if self.logger is None:
            return
        for name, value in values.items():
            if value is not None and not (isinstance(value, float) and math.isnan(value)):
                self.logger.log_scalar(name, float(value), step=step)

    def log_epoch(self, row: dict[str, Any]) -> None:
        """Append one row; the first row fixes the columns (later unknown keys are ignored)."""
        if STEP_COLUMN not in row:
            raise KeyError(f"an epoch row needs a {STEP_COLUMN!r} entry")
        new_file = self.columns is None
        if new_file:
            self.columns = list(row)
        with self.path.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            if new_file:
                writer.writeheader()
            writer.writerow(row)
        self.log_scalars(
            {k: v for k, v in row.items() if k != STEP_COLUMN and isinstance(v, int | float)},
            step=int(row[STEP_COLUMN]),
        )


def read_metrics(run_dir: str | Path) -> list[dict[str, str]]:
    """The rows of a run's ``metrics.csv``."""
    with (Path(run_dir) / METRICS_FILE).open(newline="") as f:
        return list(csv.DictReader(f))
