"""Safety-Gymnasium 1.0.0's own env steps per second: the reference for env_throughput.py.

Runs in the oracle venv (safety-gymnasium 1.0.0, gymnasium 0.28.1, mujoco 2.3.3; built as
tests/data/pointgoal1/README.md says), not in the project's environment, so it imports nothing
from this package. ``benchmarks/env_throughput.py --oracle-python <venv>/bin/python`` calls it in
the same run; alone:

    <oracle venv>/bin/python benchmarks/oracle_env_throughput.py --frames 2000 \
        --tasks SafetyPointGoal1-v0 SafetyPointCircle1-v0 [--clock cpu]

The protocol is env_throughput.py's "raw Gymnasium" column: ``gymnasium.make`` of the
Gymnasium-API id (``SafetyPointGoal1Gymnasium-v0`` for the task ``SafetyPointGoal1-v0``, with
Safety-Gymnasium's wrappers), ``reset(seed=0)``, uniform random actions drawn beforehand, a reset
whenever an episode ends. Prints one JSON object: task id -> ``{"frames_per_s": ...,
"frames_per_s_without_resets": ..., "reset_ms": ...}`` (``null`` when Safety-Gymnasium has no
such id). Safety-Gymnasium rebuilds and recompiles its world on every reset, which takes long
enough to matter, hence the second figure (the clock stopped during resets).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import gymnasium
import numpy as np

warnings.filterwarnings("ignore")
import safety_gymnasium  # noqa: E402, F401  (registers the ids with gymnasium)


def gymnasium_api_id(task: str) -> str:
    """``SafetyPointGoal1-v0`` -> ``SafetyPointGoal1Gymnasium-v0`` (aliases map to themselves)."""
    name, _, version = task.partition("-")
    return task if name.endswith("Gymnasium") else f"{name}Gymnasium-{version}"


def throughput(env_id: str, frames: int, clock) -> dict:
    env = gymnasium.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.action_space.low, env.action_space.high
    actions = rng.uniform(low, high, (frames, *env.action_space.shape))
    resets, reset_time = 0, 0.0
    start = clock()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            reset_start = clock()
            env.reset()
            reset_time += clock() - reset_start
            resets += 1
    total = clock() - start
    return {
        "frames_per_s": frames / total,
        "frames_per_s_without_resets": frames / (total - reset_time),
        "reset_ms": 1e3 * reset_time / resets if resets else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=5000)
    parser.add_argument("--tasks", nargs="+", required=True)
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall")
    args = parser.parse_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    out = {}
    for task in args.tasks:
        env_id = gymnasium_api_id(task)
        out[task] = throughput(env_id, args.frames, clock) if env_id in gymnasium.registry else None
    print(json.dumps(out))


if __name__ == "__main__":
    main()
