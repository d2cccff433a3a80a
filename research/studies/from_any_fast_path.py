"""What tensordict's ``from_any`` costs per TensorDictModule output, with and without the
package's fast path for plain tensors (s3rl_torchrl/_tensordict_fast_path.py).

    python research/studies/from_any_fast_path.py [--threads 2] [--rounds 7] \
        [--out benchmarks/results/archive/<date>/from_any_fast_path.json]

Three cases, each timed with tensordict's own ``from_any`` and with the fast path, in
interleaved rounds in one process (the patch is swapped in and out between cases):

- one ``TensorDict.from_any(tensor)`` call;
- the recipe's collector at ``experiment=paper`` settings (HalfCheetah, 10 envs, the policy
  acting): milliseconds per env step over a 2 000-frame batch;
- one eager SAC-Lag gradient step (``agent.update``, batch 256, built as the recipe builds it).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from multiseed_throughput import env_rows, paper_agents, paper_config
from tensordict import TensorDict, TensorDictBase

from s3rl_torchrl import _tensordict_fast_path
from s3rl_torchrl.trainer import Trainer

ORIGINAL = classmethod(_tensordict_fast_path._original_from_any)
FAST = classmethod(_tensordict_fast_path._from_any)


def with_from_any(variant, fn):
    def call():
        TensorDictBase.from_any = variant
        try:
            return fn()
        finally:
            TensorDictBase.from_any = FAST
    return call


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--out", type=Path,
                        default=archive_path("from_any_fast_path"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rows = []

    def report(case, unit, times, scale):
        for variant in ("tensordict's from_any", "fast path"):
            values = [t * scale for t in times[variant]]
            row = {"case": case, "variant": variant, f"median_{unit}": round(
                statistics.median(values), 4), "threads": args.threads}
            print(row, flush=True)
            rows.append(row)

    tensor = torch.zeros(256, 6)
    call = lambda: TensorDict.from_any(tensor)  # noqa: E731
    times = interleaved_rounds(
        {"tensordict's from_any": with_from_any(ORIGINAL, call),
         "fast path": with_from_any(FAST, call)},
        calls=2000, rounds=args.rounds, warmup=100)
    report("TensorDict.from_any(tensor)", "us_per_call", times, 1.0)

    batch_frames = 2000
    cfg = paper_config(args.task, 10 * batch_frames * args.rounds, False, args.threads, None,
                       batch_frames)
    cfg.collector.init_random_frames = 0
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(cfg, Path(run_dir) / "run")
        collector = trainer._make_collector()
        batches = iter(collector)
        next(batches)
        times = interleaved_rounds(
            {"tensordict's from_any": with_from_any(ORIGINAL, lambda: next(batches)),
             "fast path": with_from_any(FAST, lambda: next(batches))},
            calls=1, rounds=args.rounds, warmup=1)
        collector.shutdown()
    report("collector, experiment=paper policy", "ms_per_env_step", times,
           1e-3 / batch_frames)

    [(agent, env)] = paper_agents(cfg, 1)
    batch = env_rows(cfg, env, cfg.algo.batch_size)
    step = lambda: agent.update(batch.copy())  # noqa: E731
    times = interleaved_rounds(
        {"tensordict's from_any": with_from_any(ORIGINAL, step),
         "fast path": with_from_any(FAST, step)},
        calls=50, rounds=args.rounds, warmup=5)
    report("eager gradient step", "ms_per_step", times, 1e-3)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
