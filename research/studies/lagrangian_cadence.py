"""What the per-step Lagrangian costs: gradient steps per second with and without it.

    python research/studies/lagrangian_cadence.py [--task SafetyHalfCheetahVelocity-v1] [--threads 1]
        [--steps 200] [--rounds 15] [--no-compile] [--out benchmarks/results/archive/<date>/lagrangian_cadence.json]

One SAC-Lag agent at the paper's settings (experiment=paper: 128x128 networks, batch 256), built as the
trainer builds it (compiled unless ``--no-compile``). Cases, timed in interleaved rounds (each round times every
case in turn, so load from other processes hits them alike), CPU time of this process:

- ``gradient step``: the agent's update on a batch of the task's transitions (critics, actor,
  alpha, targets);
- ``gradient step + lambda (learned)`` / ``(pid)``: the same, then one
  ``LagrangianUpdater.after_gradient_step()`` (``algo.lagrangian_cadence=step``: one controller
  update from the window's mean, lambda written into the loss);
- ``lambda update alone``: ``after_gradient_step()`` by itself, per controller.

Under ``cadence=collect`` a gradient step is the first case exactly (lambda moves once per
collect, outside the gradient steps).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import interleaved_rounds, write_report
from multiseed_throughput import env_rows, paper_agents, paper_config

from s3rl_torchrl.objectives import LagrangianUpdater, LearnedLagrangian, PIDLagrangian
from s3rl_torchrl.trainer.loop import compile_loss


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--steps", type=int, default=200, help="calls per case per round")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--compile", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    cfg = paper_config(args.task, 0, args.compile, args.threads, None, 10_000)
    ((agent, env),) = paper_agents(cfg, 1, compile_loss if args.compile else None)
    # Real transitions of the task, one batch (the sampler's cost is not what differs).
    batch = env_rows(cfg, env, cfg.algo.batch_size)
    limit = cfg.task.cost_limit
    updaters = {
        "learned": LagrangianUpdater(
            LearnedLagrangian(limit, lr=1e-4), agent.loss, cadence="step", window=20
        ),
        "pid": LagrangianUpdater(
            PIDLagrangian(1e-6, 5e-7, 1e-7, limit, error_ema=0.95, cost_ema=0.95,
                          derivative_delay=10, ki_inside_integral=True),
            agent.loss, cadence="step", window=20,
        ),
    }
    for updater in updaters.values():  # a window with costs over the limit: lambda moves
        updater.observe(torch.tensor([[15.0]] * 20), frames=1)

    def step():
        agent.update(batch)

    cases = {
        "gradient step": step,
        "gradient step + lambda (learned)": lambda: (step(), updaters["learned"].after_gradient_step()),
        "gradient step + lambda (pid)": lambda: (step(), updaters["pid"].after_gradient_step()),
        "lambda update alone (learned)": updaters["learned"].after_gradient_step,
        "lambda update alone (pid)": updaters["pid"].after_gradient_step,
    }
    times = interleaved_rounds(cases, args.steps, args.rounds, warmup=20, clock=time.process_time)
    results = {}
    for name, values in times.items():
        median = statistics.median(values)
        results[name] = {
            "median_us": round(median, 2),
            "min_us": round(min(values), 2),
            "max_us": round(max(values), 2),
            "calls_per_s": round(1e6 / median, 1),
        }
    base = results["gradient step"]["median_us"]
    for kind in ("learned", "pid"):
        with_lambda = results[f"gradient step + lambda ({kind})"]["median_us"]
        results[f"gradient step + lambda ({kind})"]["slowdown_vs_gradient_step"] = round(
            with_lambda / base - 1, 4
        )
    print(f"{'case':38s} {'median us':>10s} {'min':>9s} {'max':>9s} {'per s':>9s}")
    for name, r in results.items():
        print(f"{name:38s} {r['median_us']:10.1f} {r['min_us']:9.1f} {r['max_us']:9.1f} "
              f"{r['calls_per_s']:9.1f}")
    if args.out is not None:
        write_report(args.out, {
            "task": args.task, "threads": args.threads, "compiled": args.compile,
            "steps_per_round": args.steps, "rounds": args.rounds, "clock": "process_time",
            "results": results,
        })


if __name__ == "__main__":
    main()
