"""CPU time of a recorded step per task family (docs/video.md, "What a recorded episode costs").

    python benchmarks/video_timing.py --steps 100

For each family's task (docs/make_clips.py's CLIPS), the same seeded random-action rollout of
``--steps`` steps: without pixels (simulation), with 256 x 256 frames (make_video_env: render
and the unsafe-step overlay), the overlay alone, and writing the frames to mp4. Times are the
process's CPU time (``time.process_time``, Mesa's render threads included), so that they do
not depend on what else the cores run; per step, in ms.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def cpu_ms_per_step(steps: int, fn, *args) -> tuple[float, object]:
    """``fn(*args)``'s CPU time divided by ``steps`` (ms), and what it returned."""
    start = time.process_time()
    out = fn(*args)
    return 1000 * (time.process_time() - start) / steps, out


def rollout(env, steps: int):
    return env.rollout(steps, break_when_any_done=False)


def write_mp4(frames) -> None:
    from s3rl_torchrl.envs.video import VideoWriter

    with tempfile.TemporaryDirectory() as tmp, VideoWriter(Path(tmp, "v.mp4")) as writer:
        for frame in frames:
            writer.append(frame)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()

    import torch

    from docs.make_clips import CLIPS
    from s3rl_torchrl.envs import make_env
    from s3rl_torchrl.envs.video import make_video_env
    from s3rl_torchrl.transforms import mark_frame

    torch.set_num_threads(1)
    print("| family | task | simulation | render (256 px) | overlay | mp4 writing |")
    print("|---|---|---:|---:|---:|---:|")
    for family, task in CLIPS.items():
        steps = args.steps
        env = make_env(task, seed=0)
        torch.manual_seed(0)
        sim, _ = cpu_ms_per_step(steps, rollout, env, steps)
        env.close()
        env = make_video_env(task, seed=0)
        rollout(env, 2)  # the first frame builds the renderer
        torch.manual_seed(0)
        total, recorded = cpu_ms_per_step(steps, rollout, env, steps)
        env.close()
        frames = recorded["next", "pixels"].numpy()
        overlay, _ = cpu_ms_per_step(steps, lambda fs: [mark_frame(f, 1.0, 2.0, 3.0) for f in fs],
                                     frames)
        writing, _ = cpu_ms_per_step(steps, write_mp4, frames)
        render = total - sim - overlay
        print(f"| {family} | {task} | {sim:.1f} | {render:.1f} | {overlay:.1f} | {writing:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
