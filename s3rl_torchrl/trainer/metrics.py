"""Run metrics: torchrl's loggers plus one ``metrics.csv`` table per run (one row per epoch).

On resume both continue from the checkpoint's frame count: rows logged after that checkpoint
(by the interrupted run) are dropped first, so the files have neither gaps nor duplicates.
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


def make_torchrl_logger(
    backend: str, run_dir: Path, exp_name: str, project: str, wandb_mode: str
) -> Logger | None:
    """One of torchrl's loggers, writing inside the run directory (no server needed)."""
    log_dir = run_dir / "logs"
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


def _trim_csv(path: Path, max_step: int, step_index: int, has_header: bool) -> None:
    """Drop rows whose step is beyond ``max_step`` (written after the last checkpoint)."""
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    header, body = (rows[:1], rows[1:]) if has_header else ([], rows)
    kept = [r for r in body if r and float(r[step_index]) <= max_step]
    if len(kept) != len(body):
        with path.open("w", newline="") as f:
            csv.writer(f).writerows(header + kept)


def ensure_new_run_dir(run_dir: str | Path) -> None:
    """Refuse to start a new run where one already wrote its metrics (its files stay intact)."""
    if (Path(run_dir) / METRICS_FILE).exists():
        raise FileExistsError(
            f"{run_dir} already holds a run ({METRICS_FILE}); continue it with "
            f"resume={run_dir} or train into a new directory."
        )


class RunMetrics:
    """Writes epoch rows to ``metrics.csv`` and every scalar to a torchrl logger."""

    def __init__(self, run_dir: Path, logger: Logger | None, resume_frames: int | None = None):
        self.path = Path(run_dir) / METRICS_FILE
        self.logger = logger
        self.columns: list[str] | None = None
        if resume_frames is None:
            ensure_new_run_dir(run_dir)
        if self.path.exists():
            with self.path.open(newline="") as f:
                self.columns = next(csv.reader(f), None)
            _trim_csv(self.path, resume_frames, self.columns.index(STEP_COLUMN), True)
        scalars = getattr(getattr(logger, "experiment", None), "log_dir", None)
        if resume_frames is not None and scalars is not None:
            for file in Path(scalars, "scalars").glob("*.csv"):
                _trim_csv(file, resume_frames, 0, False)

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
