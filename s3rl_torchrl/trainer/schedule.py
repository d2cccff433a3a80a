"""When gradient steps happen: the rule the loop follows, and the count it gives for a config.

The loop owes ``update_per_step`` gradient steps per frame of every collected batch that ends at
or after ``init_random_frames`` (FSRL learns only after the uniform-random warm-up) and leaves at
least ``batch_size`` transitions in the replay buffer; owed fractions carry over to the next
batch. :func:`planned_gradient_steps` replays that rule batch by batch without collecting, so a
config that would never take a gradient step is refused before anything is built
(:meth:`~s3rl_torchrl.trainer.config.TrainConfig.check`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from s3rl_torchrl.trainer.config import AlgoConfig, CollectorConfig


def updates_owed(
    frames: int, batch_frames: int, stored: int, collector: CollectorConfig, algo: AlgoConfig
) -> float:
    """Gradient steps owed for a batch of ``batch_frames`` frames that brought the run to
    ``frames`` frames and left ``stored`` transitions in the replay buffer."""
    if frames < collector.init_random_frames:
        return 0.0
    if stored < algo.batch_size:
        return 0.0
    return algo.update_per_step * batch_frames


def collector_batch_frames(collector: CollectorConfig) -> int:
    """Frames per collected batch: torchrl's collector rounds up to whole steps of every env."""
    return math.ceil(collector.frames_per_batch / collector.num_envs) * collector.num_envs


def stored_transitions(batches: int, collector: CollectorConfig, algo: AlgoConfig) -> int:
    """Replay-buffer length after ``batches`` batches: with n-step returns (``n_step > 1``) the
    n-step transform holds back the last ``n_step`` frames of every env copy until the next
    batch (torchrl's ``MultiStepTransform`` buffering); the buffer keeps ``buffer_size`` at most."""
    steps_per_env = batches * collector_batch_frames(collector) // collector.num_envs
    held_back = algo.n_step if algo.n_step > 1 else 0
    return min(algo.buffer_size, collector.num_envs * max(0, steps_per_env - held_back))


def planned_gradient_steps(
    collector: CollectorConfig, algo: AlgoConfig, stop_at: int | None = None
) -> int:
    """The number of gradient steps a run of this config takes (collector and algo settings);
    with ``stop_at``, counting stops once that many are reached."""
    batch_frames = collector_batch_frames(collector)
    batches = math.ceil(collector.total_frames / batch_frames)
    pending, steps = 0.0, 0
    for k in range(1, batches + 1):
        stored = stored_transitions(k, collector, algo)
        pending += updates_owed(k * batch_frames, batch_frames, stored, collector, algo)
        # The loop subtracts 1.0 per step; below 2**53 that is exact, so floor gives the same.
        whole = math.floor(pending)
        steps += whole
        pending -= whole
        if stop_at is not None and steps >= stop_at:
            break
    return steps
