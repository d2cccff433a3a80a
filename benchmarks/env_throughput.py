"""Env steps per second: raw Gymnasium vs ``make_env`` with 1 and 10 copies.

    python benchmarks/env_throughput.py [--frames 5000] [--tasks ...] [--out benchmarks/results/env_throughput.json]
    python benchmarks/env_throughput.py --family bullet circle --batchings sync_vector \
        --out benchmarks/results/env_throughput_bullet_circle.json

Random actions; a "step" is one transition of one env copy (frames). ``--clock cpu`` times with
the process's CPU time instead of wall time: on a shared machine it drops the time other
processes take from this one (single-process batchings only: ``sync_vector``, ``serial``). "raw Gymnasium" steps
``gymnasium.make`` of the id ``make_env`` builds (for the Bullet tasks: the upstream env with
this package's reset-only seeding wrapper), without torchrl. Results go to a JSON file and a
Markdown table on stdout (pasted into docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from _report import write_report

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=5000)
    parser.add_argument("--tasks", nargs="*", default=None,
                        help="task ids (default: the six v1 velocity tasks, or --family's)")
    parser.add_argument("--family", nargs="*", default=[],
                        help="every main id of these families (velocity, bullet, circle)")
    parser.add_argument("--batchings", nargs="*", default=["sync_vector", "serial", "async_vector", "parallel"])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/env_throughput.json"))
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall")
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

    rows = []
    for task in tasks:
        row = {"task": task, "raw_gymnasium": raw_gymnasium(task, args.frames)}
        row["make_env_1"] = torchrl_env(task, args.frames, 1, "serial")
        for batching in args.batchings:
            row[f"make_env_10_{batching}"] = torchrl_env(task, args.frames, 10, batching)
        rows.append(row)
        print(json.dumps({k: round(v) if isinstance(v, float) else v for k, v in row.items()}))

    result = {
        "unit": f"env steps (frames) per second of {args.clock} time",
        "rows": rows,
    }
    write_report(args.out, result)
    columns = [c for c in rows[0] if c != "task"]
    print("\n| task | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for row in rows:
        print(f"| {row['task']} | " + " | ".join(f"{row[c]:,.0f}" for c in columns) + " |")


if __name__ == "__main__":
    main()
