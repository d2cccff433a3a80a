"""Env steps per second of every algorithm of the registry at its default settings, one run.

    python research/studies/algo_throughput.py [--frames 4000] [--task SafetyHalfCheetahVelocity-v1]
        [--algos s3rl sac_lag ...] [--out benchmarks/results/archive/<date>/algo_throughput.json]

Default settings: ``s3rl-train algo=<name>`` as composed (experiment=quick: 4 training envs,
1000-frame collects, batch 256; off-policy 0.5 gradient steps per frame after a 5000-frame
uniform-random warm-up; PPO family 4 passes of 4 minibatches per collect and no warm-up;
torch.compile on for the SAC family, threads=1). Only the evaluation cadence is changed (one
evaluation, after the clock stops). The clock runs over ``--frames`` frames that start after the
first collect that took gradient steps (it pays the compile), so every algorithm is timed while
it learns: collection, storage, gradient steps, Lagrangian and contrastive phases. Reported per
algorithm: wall-clock steps/s, this process's CPU seconds over the window (``time.process_time``:
what the algorithm costs whatever else runs) and the 1-minute load average before and after.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
from _report import archive_path, recipe_config, write_report

from s3rl_torchrl.algorithms import family_of
from s3rl_torchrl.trainer import Trainer
from s3rl_torchrl.trainer.config import ALGO_NAMES


def _mark(trainer: Trainer) -> tuple[int, int, float, float]:
    c = trainer.counters
    return c.frames, c.grad_steps, time.perf_counter(), time.process_time()


class MarkedTrainer(Trainer):
    """A Trainer that records (frames, gradient steps, wall time, CPU time) after each collect's
    gradient steps, before any evaluation."""

    marks: list[tuple[int, int, float, float]]
    _before_eval: tuple[int, int, float, float] | None = None

    def _end_epoch(self) -> None:
        self._before_eval = _mark(self)
        super()._end_epoch()

    def _finish_batch(self) -> bool:
        self._before_eval = None
        done = super()._finish_batch()
        self.marks.append(self._before_eval or _mark(self))
        return done


def measure(algo: str, task: str, frames: int) -> dict:
    probe = recipe_config(f"algo={algo}")
    schedule = family_of(probe.algo).schedule(probe.collector, probe.algo)
    batch = probe.collector.frames_per_batch
    # Frames up to the end of the first collect that learns, then the measured window.
    first = next(k for k in range(batch, 10**9, batch) if k >= schedule.warmup_frames())
    total = first + -(-frames // batch) * batch
    cfg = recipe_config(
        f"algo={algo}",
        f"task={task}",
        f"collector.total_frames={total}",
        f"collector.frames_per_epoch={total}",
        "eval.final_episodes=1",
    )
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = MarkedTrainer(cfg, run_dir)
        trainer.marks = []
        trainer.run()
    load_after = os.getloadavg()[0]
    start = next(m for m in trainer.marks if m[0] >= first)
    end = trainer.marks[-1]
    measured, steps = end[0] - start[0], end[1] - start[1]
    wall, cpu = end[2] - start[2], end[3] - start[3]
    return {
        "algo": algo,
        "family": family_of(algo).name,
        "schedule": schedule.name,
        "task": task,
        "compile": cfg.compile,
        "threads": cfg.threads,
        "frames_measured": measured,
        "gradient_steps_measured": steps,
        "wall_seconds": round(wall, 2),
        "cpu_seconds": round(cpu, 2),
        "env_steps_per_s": round(measured / wall, 1),
        "env_steps_per_cpu_s": round(measured / cpu, 1),
        "gradient_steps_per_s": round(steps / wall, 1),
        "contrastive_phases": trainer.counters.contrastive_phases,
        "load_1min_before": round(load_before, 2),
        "load_1min_after": round(load_after, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4000)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--algos", nargs="*", default=list(ALGO_NAMES))
    parser.add_argument("--out", type=Path, default=archive_path("algo_throughput"))
    args = parser.parse_args()
    uptime_before = Path("/proc/loadavg").read_text().split()[:3]
    rows = []
    for algo in args.algos:
        row = measure(algo, args.task, args.frames)
        print(row, flush=True)
        rows.append(row)
    uptime_after = Path("/proc/loadavg").read_text().split()[:3]
    print("| algo | schedule | gradient steps | env steps/s (wall) | env steps/CPU s | load |")
    print("|---|---|---:|---:|---:|---|")
    for r in rows:
        print(
            f"| {r['algo']} | {r['schedule']} | {r['gradient_steps_measured']} | "
            f"{r['env_steps_per_s']} | {r['env_steps_per_cpu_s']} | "
            f"{r['load_1min_before']}-{r['load_1min_after']} |"
        )
    write_report(
        args.out,
        {
            "cpus": os.cpu_count(),
            "loadavg_before": uptime_before,
            "loadavg_after": uptime_after,
            "rows": rows,
        },
    )


if __name__ == "__main__":
    main()
