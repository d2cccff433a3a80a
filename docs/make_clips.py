"""The clips of docs/media/: one short GIF per task family, unsafe steps marked (docs/video.md).

    make clips                                    # = python docs/make_clips.py
    python docs/make_clips.py --run SafetyPointGoal1-v0=outputs/s3rl/SafetyPointGoal1-v0/seed10/<time>

For each family's task (:data:`CLIPS`) it records one deterministic episode start of the
policy of a run: the run given with ``--run TASK=RUN_DIR`` (a run directory, checkpoint
directory or ``state.pt``), else a run it trains itself, S3RL for ``--frames`` frames
(``experiment=tiny``'s small networks; into ``--work``). A policy trained that briefly is not
the delivered one: give the runs of Table 1 to show those. Each clip is ``--steps`` steps of
``--size`` x ``--size`` pixels (what keeps it under 1 MB); the command prints each file's size.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

#: family -> the task its clip shows.
CLIPS = {
    "velocity": "SafetyHalfCheetahVelocity-v1",
    "circle": "SafetyPointCircle1-v0",
    "goal": "SafetyPointGoal1-v0",
    "bullet": "SafetyBallRun-v0",
}
MAX_CLIP_BYTES = 1_000_000


def train_short_run(task: str, frames: int, run_dir: Path) -> Path:
    """S3RL on ``task`` for ``frames`` frames with ``experiment=tiny``'s networks."""
    from hydra import compose, initialize_config_dir

    from s3rl_torchrl.recipes import config_dir
    from s3rl_torchrl.trainer import register_configs, train, validate

    if (run_dir / "checkpoints" / "latest").exists():
        return run_dir  # trained by an earlier call
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        overrides = [
            "experiment=tiny",
            "algo=s3rl",
            f"task={task}",
            f"collector.total_frames={frames}",
            "collector.frames_per_epoch=1000",
            "collector.init_random_frames=500",
            "logger=none",
        ]
        cfg = validate(compose(config_name="train", overrides=overrides))
    train(cfg, run_dir)
    return run_dir


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--run", action="append", default=[], metavar="TASK=RUN_DIR")
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--size", type=int, default=160)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "media")
    parser.add_argument("--work", type=Path, default=REPO / "outputs" / "clips")
    parser.add_argument("--family", action="append", choices=sorted(CLIPS), default=None)
    args = parser.parse_args(argv)

    from s3rl_torchrl.envs.video import make_video_env
    from s3rl_torchrl.trainer.evaluate_checkpoint import TEST_SEED_OFFSET, load_policy
    from s3rl_torchrl.trainer.evaluation import record_video

    given = dict(item.split("=", 1) for item in args.run)
    for family in args.family or CLIPS:
        task = CLIPS[family]
        start = time.perf_counter()
        run = given.get(task) or train_short_run(task, args.frames, args.work / task)
        actor, cfg = load_policy(run)
        env = make_video_env(task, seed=cfg.seed + TEST_SEED_OFFSET, size=args.size)
        path = args.out / f"{family}_{task}.gif"
        try:
            record_video(env, actor, path, max_steps=args.steps)
        finally:
            env.close()
        size = path.stat().st_size
        flag = "" if size <= MAX_CLIP_BYTES else f"  (over {MAX_CLIP_BYTES} bytes: lower --steps)"
        print(f"{path.relative_to(REPO)}: {size / 1000:.0f} kB, {run}, "
              f"{time.perf_counter() - start:.0f} s{flag}")


if __name__ == "__main__":
    main()
