"""What dynamo's guards cost a compiled gradient step, and what the recipe's guard filter saves.

    python research/studies/compile_guards.py [--threads 2] [--calls 100] [--rounds 7] \
        [--out benchmarks/results/archive/<date>/guard_filter.json]

Before every call of a compiled function, dynamo checks its guards: that the tensors, the
global state and every Python attribute the trace read (of the loss, its networks and their
submodules) are as they were when it compiled. For a SAC-Lag loss that is hundreds of checks.
``compile_loss`` (trainer/loop.py) keeps the tensor and global-state guards and drops the ones
on module attributes (``torch.compiler.skip_guard_on_all_nn_modules_unsafe``); this script
times the single-seed joint gradient step (``agent.update``, built as the recipe builds it at
``experiment=paper`` settings, HalfCheetah, batch 256) compiled three ways, in interleaved
rounds in one process: torch's default guards, the recipe's filter, and tensor guards only
(``keep_tensor_guards_unsafe``, the least checking torch offers besides none).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from multiseed_throughput import env_rows, paper_agents, paper_config

FILTERS = {
    "default guards": None,
    "recipe (no module-attribute guards)": torch.compiler.skip_guard_on_all_nn_modules_unsafe,
    "tensor guards only": torch.compiler.keep_tensor_guards_unsafe,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--calls", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--out", type=Path, default=archive_path("guard_filter"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = paper_config(args.task, 0, True, args.threads, None, 10_000)
    cases = {}
    for name, guard_filter in FILTERS.items():
        options = {} if guard_filter is None else {"guard_filter_fn": guard_filter}

        def compile_fn(fn, options=options):
            return torch.compile(fn, isolate_recompiles=True, options=options)

        [(agent, env)] = paper_agents(cfg, 1, compile_fn)
        batch = env_rows(cfg, env, cfg.algo.batch_size)
        cases[name] = lambda agent=agent, batch=batch: agent.update(batch.copy())
    times = interleaved_rounds(cases, calls=args.calls, rounds=args.rounds, warmup=10)
    base = statistics.median(times["default guards"])
    rows = []
    for name, values in times.items():
        row = {
            "case": name,
            "median_ms_per_gradient_step": round(statistics.median(values) / 1e3, 3),
            "min_ms_per_gradient_step": round(min(values) / 1e3, 3),
            "saved_ms_vs_default": round((base - statistics.median(values)) / 1e3, 3),
            "threads": args.threads,
        }
        print(row, flush=True)
        rows.append(row)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
