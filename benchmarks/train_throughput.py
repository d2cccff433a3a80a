"""Env steps per second of the whole S3RL recipe at the paper's settings, eager and compiled.

    python benchmarks/train_throughput.py [--frames 50000] [--task SafetyHalfCheetahVelocity-v1]
        [--modes eager compiled] [--threads 1] [--out benchmarks/results/archive/<date>/train_throughput.json]

Paper settings (experiment=paper): 10 training envs, 0.2 gradient steps per frame, batch 256,
128x128 networks, n-step 2, PID Lagrangian, the contrastive phase every 1000 gradient steps.
The clock runs over ``--frames`` frames *after* the first epoch (20 000 frames on HalfCheetah:
the uniform-random warm-up collect, its gradient steps and the first compilation), and
evaluation time is subtracted: what is left is collection, storage, gradient steps and
contrastive phases. ``--frames`` is rounded up to whole epochs. Hours per 1M steps = 1e6 / (steps/s) / 3600.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from _report import archive_path, recipe_config, write_report

from s3rl_torchrl.trainer import Trainer


def measure(task: str, frames: int, compiled: bool, threads: int,
            experiment: str = "paper") -> dict:
    """One run of the recipe at ``experiment`` (the harness's quick size: ``tiny``)."""
    paper = recipe_config(f"experiment={experiment}", f"task={task}")
    epoch = paper.collector.frames_per_epoch  # the first epoch is the warm-up
    frames = -(-frames // epoch) * epoch
    cfg = recipe_config(
        f"experiment={experiment}",
        f"task={task}",
        f"collector.total_frames={epoch + frames}",
        f"compile={str(compiled).lower()}",
        f"threads={threads}",
    )
    marks: list[tuple[int, float, float]] = []  # (frames, time, eval seconds)

    def on_epoch_end(trainer, row):
        marks.append((row["frames"], time.perf_counter(), row["eval/seconds"]))

    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(cfg, run_dir, on_epoch_end=on_epoch_end)
        trainer.cfg.eval.final_episodes = 1
        start = time.perf_counter()
        trainer.run()
    # The first mark closes the warm-up epoch; measure from there to the last one.
    (f0, t0, _), (f1, t1, _) = marks[0], marks[-1]
    eval_seconds = sum(e for _, _, e in marks[1:])
    seconds = t1 - t0 - eval_seconds
    steps_per_s = (f1 - f0) / seconds
    return {
        "mode": "compiled" if compiled else "eager",
        "task": task,
        "frames_measured": f1 - f0,
        "seconds": round(seconds, 2),
        "env_steps_per_s": round(steps_per_s, 1),
        "hours_per_1M_steps": round(1e6 / steps_per_s / 3600, 3),
        "gradient_steps": trainer.counters.grad_steps,
        "contrastive_phases": trainer.counters.contrastive_phases,
        "warmup_seconds_incl_first_compile": round(t0 - start, 2),
        "threads": threads,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=50_000)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--modes", nargs="*", default=["eager", "compiled"])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=archive_path("train_throughput"))
    args = parser.parse_args()
    rows = []
    for mode in args.modes:
        row = measure(args.task, args.frames, mode == "compiled", args.threads)
        print(json.dumps(row), flush=True)
        rows.append(row)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
