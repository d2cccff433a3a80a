"""What torchrl's ``compile_policy`` does to collection: the recipe's collector (SAC-Lag's
policy, ``experiment=paper``, SafetyHalfCheetahVelocity-v1, 10 env copies) with the policy
eager, as the recipe runs it, and with ``Collector(..., compile_policy=...)`` (issue 28's
"batch the policy call").

    python research/studies/collector_compile_policy.py [--frames 2000] [--rounds 7] \
        [--out benchmarks/results/archive/<date>/collector_compile_policy.json]

Each case is one collector over the same env (built as the trainer builds it), timed in
interleaved rounds in one process, one collect of ``--frames`` frames per round, with this
process's CPU time (the cores are shared). Also recorded: whether the compiled policy draws the
same actions as the eager one from the same RNG state (a change the recipe's seeded runs
would see).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from multiseed_throughput import paper_agents, paper_config
from torchrl.collectors import Collector


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument(
        "--out", type=Path, default=archive_path("collector_compile_policy")
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = paper_config(args.task, args.frames, False, args.threads, None, args.frames)
    ((agent, env),) = paper_agents(cfg, 1)
    variants = {"policy eager (the recipe)": None, "compile_policy": {"dynamic": False}}
    collectors = {
        name: iter(
            Collector(env, agent.policy, frames_per_batch=args.frames, total_frames=-1,
                      compile_policy=compile_policy)
        )
        for name, compile_policy in variants.items()
    }
    cases = {name: (lambda it=it: next(it)) for name, it in collectors.items()}
    times = interleaved_rounds(
        cases, calls=1, rounds=args.rounds, warmup=2, clock=time.process_time
    )

    # Same RNG state, same observation: does the compiled policy draw the same action?
    observation = env.reset()
    eager_policy = agent.policy
    compiled_policy = torch.compile(agent.policy, dynamic=False)
    with torch.no_grad():  # as the collector calls it
        torch.manual_seed(0)
        eager_action = eager_policy(observation.clone())["action"]
        torch.manual_seed(0)
        compiled_action = compiled_policy(observation.clone())["action"]
    action_difference = float((eager_action - compiled_action).abs().max())

    rows = []
    for name, values in times.items():
        per_step = [v / args.frames for v in values]
        row = {"case": name, "median_us_per_env_step": round(statistics.median(per_step), 1),
               "min_us_per_env_step": round(min(per_step), 1),
               "max_us_per_env_step": round(max(per_step), 1),
               "frames_per_round": args.frames, "env_copies": cfg.collector.num_envs,
               "threads": args.threads}
        print(row, flush=True)
        rows.append(row)
    print({"max_abs_action_difference_same_seed": action_difference})
    write_report(args.out, {"rows": rows,
                            "max_abs_action_difference_same_seed": action_difference})


if __name__ == "__main__":
    main()
