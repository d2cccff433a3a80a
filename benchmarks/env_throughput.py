"""Env steps per second: raw Gymnasium vs ``make_env`` with 1 and 10 copies.

    python benchmarks/env_throughput.py [--frames 5000] [--tasks ...] [--out benchmarks/results/archive/<date>/env_throughput.json]
    python benchmarks/env_throughput.py --family bullet circle --batchings sync_vector \
        --out benchmarks/results/archive/<date>/env_throughput_bullet_circle.json
    python benchmarks/env_throughput.py --family goal circle --tasks SafetyHalfCheetahVelocity-v1 \
        --batchings sync_vector --clock cpu --oracle-python /work/oracle-venv/bin/python \
        --out benchmarks/results/archive/<date>/env_throughput_goal.json

Random actions; a "step" is one transition of one env copy (frames). ``--clock cpu`` times with
the process's CPU time instead of wall time: on a shared machine it drops the time other
processes take from this one (single-process batchings only: ``sync_vector``, ``serial``). "raw Gymnasium" steps
``gymnasium.make`` of the id ``make_env`` builds (for the Bullet tasks: the upstream env with
this package's reset-only seeding wrapper), without torchrl. ``--oracle-python`` adds, in the same
run, Safety-Gymnasium 1.0.0's own env under the same protocol, measured by
``oracle_env_throughput.py`` in the given interpreter (the oracle venv of
tests/data/pointgoal1/README.md; ``null`` for tasks Safety-Gymnasium does not have). Results go
to a JSON file and a Markdown table on stdout (pasted into docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from _report import archive_path, write_report

import s3rl_torchrl  # noqa: F401  (registers the tasks)
from s3rl_torchrl.envs import get_task, make_env, require_task_module, task_names

ROBOTS = ["HalfCheetah", "Hopper", "Walker2d", "Swimmer", "Ant", "Humanoid"]


CLOCK = time.perf_counter


def raw_gymnasium(task: str, frames: int) -> float:
    spec = get_task(task)
    require_task_module(spec)
    env = gym.make(spec.registered_as or task)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(
        env.action_space.low, env.action_space.high, (frames, *env.action_space.shape)
    )
    actions = actions.astype(np.float32)
    start = CLOCK()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return frames / (CLOCK() - start)


def torchrl_env(task: str, frames: int, num_envs: int, batching: str) -> float:
    env = make_env(task, num_envs=num_envs, seed=0, batching=batching)
    env.rollout(10, break_when_any_done=False)  # warm-up (spec caches, worker start)
    steps = max(1, frames // num_envs)
    start = CLOCK()
    env.rollout(steps, break_when_any_done=False)
    elapsed = CLOCK() - start
    env.close()
    return steps * num_envs / elapsed


def safety_gymnasium_reference(python: str, tasks: list[str], frames: int, clock: str) -> dict:
    """Safety-Gymnasium's own steps/s per task (with and without its resets, and the reset
    time), from oracle_env_throughput.py in ``python``."""
    script = Path(__file__).resolve().parent / "oracle_env_throughput.py"
    out = subprocess.run(
        [python, str(script), "--frames", str(frames), "--clock", clock, "--tasks", *tasks],
        check=True, capture_output=True, text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=5000)
    parser.add_argument("--tasks", nargs="*", default=None,
                        help="task ids (default: the six v1 velocity tasks, or --family's)")
    parser.add_argument("--family", nargs="*", default=[],
                        help="every main id of these families (velocity, bullet, circle, goal)")
    parser.add_argument("--batchings", nargs="*", default=["sync_vector", "serial", "async_vector", "parallel"])
    parser.add_argument("--out", type=Path, default=archive_path("env_throughput"))
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall")
    parser.add_argument("--oracle-python", default=None,
                        help="interpreter of the Safety-Gymnasium 1.0.0 oracle venv: adds its own "
                             "env's steps/s (columns safety_gymnasium_1.0*)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.clock == "cpu":
        if set(args.batchings) - {"sync_vector", "serial"}:
            parser.error("--clock cpu times this process only: use --batchings sync_vector serial")
        global CLOCK
        CLOCK = time.process_time
    tasks = list(args.tasks or [])
    for family in args.family:
        tasks += task_names(include_variants=False, include_aliases=False, family=family)
    if not tasks:
        tasks = [f"Safety{r}Velocity-v1" for r in ROBOTS]

    load_start = os.getloadavg()  # other jobs' load, recorded beside the numbers
    rows = []
    for task in tasks:
        row = {"task": task, "raw_gymnasium": raw_gymnasium(task, args.frames)}
        if args.oracle_python:  # task by task, so that load changes hit both alike
            reference = safety_gymnasium_reference(
                args.oracle_python, [task], args.frames, args.clock)[task] or {}
            row["safety_gymnasium_1.0"] = reference.get("frames_per_s")
            row["safety_gymnasium_1.0_without_resets"] = reference.get(
                "frames_per_s_without_resets")
            row["safety_gymnasium_1.0_reset_ms"] = reference.get("reset_ms")
        row["make_env_1"] = torchrl_env(task, args.frames, 1, "serial")
        for batching in args.batchings:
            row[f"make_env_10_{batching}"] = torchrl_env(task, args.frames, 10, batching)
        rows.append(row)
        print(json.dumps({k: round(v) if isinstance(v, float) else v for k, v in row.items()}))

    result = {
        "unit": f"env steps (frames) per second of {args.clock} time",
        "load_average_1_5_15_min": {"start": load_start, "end": os.getloadavg()},
        "rows": rows,
    }
    write_report(args.out, result)
    columns = [c for c in rows[0] if c != "task"]
    print("\n| task | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for row in rows:
        cells = ("–" if row[c] is None else f"{row[c]:,.0f}" for c in columns)
        print(f"| {row['task']} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
