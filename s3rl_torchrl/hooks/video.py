"""A video of the policy every ``eval.video_interval`` epochs, through the run's logger
(``eval.video_interval``, off by default; docs/video.md).

torchrl's :class:`~torchrl.record.VideoRecorder` on a rendering copy of the evaluation env
records one deterministic episode after the epoch's evaluation, unsafe steps marked
(:class:`~s3rl_torchrl.transforms.CostOverlay`), and hands it to the logger's ``log_video`` at
the epoch's frame count: TensorBoard and W&B show it beside the scalars; the CSV logger writes
``logs/<exp>/videos/eval/video_<frames>.mp4`` (``trainer/metrics.py``).

The copy is built like the run's first test env (its task and seed) but is not the test env:
rendering there would make every epoch's evaluation pay for frames (40-300 ms a step on a
CPU, docs/video.md), and the video's episodes would move the test env's seeded stream, which
a resume restores. So videos change no number of the run.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.record import VideoRecorder

from s3rl_torchrl.envs import get_task
from s3rl_torchrl.envs.video import VIDEO_FPS, make_video_env
from s3rl_torchrl.hooks.base import HookHost, TrainerHook

__all__ = ["EvalVideo"]

#: The logger's tag of the videos (TensorBoard: the "Images" tab's ``eval/video``).
VIDEO_TAG = "eval/video"
#: Frame size of training videos (pixels, square): a TensorBoard video is a GIF of float32
#: frames while it is encoded, so 500 frames of 160 x 160 hold ~150 MB at most.
TRAINING_VIDEO_SIZE = 160
#: Frames kept per video: longer episodes keep every k-th frame (each kept frame is still
#: marked for its own step; the running cost on it counts every step).
MAX_VIDEO_FRAMES = 500


class EvalVideo(TrainerHook):
    """Every ``interval`` epochs, one deterministic episode of at most ``max_steps`` steps of
    ``task`` (env seeded with ``seed``), logged by the trainer's logger as ``eval/video``."""

    def __init__(
        self, task: str, seed: int, interval: int, max_steps: int, size: int = TRAINING_VIDEO_SIZE
    ) -> None:
        if interval < 1:
            raise ValueError(f"EvalVideo needs interval >= 1, got {interval}.")
        self.task, self.seed, self.interval = task, seed, interval
        self.max_steps, self.size = max_steps, size
        self.skip = math.ceil((max_steps + 1) / MAX_VIDEO_FRAMES)
        self.env: TransformedEnv | None = None
        self.recorder: VideoRecorder | None = None

    @classmethod
    def for_run(cls, cfg) -> EvalVideo:
        """The run ``cfg``'s hook: its task, its first test env's seed, its episode length."""
        from s3rl_torchrl.trainer.evaluate_checkpoint import TEST_SEED_OFFSET

        max_steps = cfg.eval.max_steps or get_task(cfg.task.name).max_episode_steps
        return cls(cfg.task.name, cfg.seed + TEST_SEED_OFFSET, cfg.eval.video_interval, max_steps)

    def register(self, host: HookHost, name: str) -> None:
        host.register_op("epoch_end", self.record)

    def _build(self, logger) -> None:
        self.env = make_video_env(self.task, seed=self.seed, size=self.size)
        self.recorder = VideoRecorder(
            logger,
            VIDEO_TAG,
            skip=self.skip,
            make_grid=False,
            fps=max(1, round(VIDEO_FPS / self.skip)),
        )
        self.env.append_transform(self.recorder)

    def record(self, trainer, row: dict[str, Any]) -> None:
        """``epoch_end`` op: on every ``interval``-th epoch, record and log one episode."""
        logger = trainer.metrics.logger
        if row["epoch"] % self.interval or logger is None:
            return
        if self.env is None:
            self._build(logger)
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            self.env.rollout(self.max_steps, trainer.agent.actor)
        self.recorder.dump(step=int(row["frames"]))
