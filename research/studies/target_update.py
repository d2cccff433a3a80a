"""Microseconds per target update: torchrl's ``SoftUpdate`` against ``ForeachSoftUpdate``.

    python research/studies/target_update.py [--calls 1000] [--rounds 7] \
        [--out benchmarks/results/archive/<date>/target_update.json]

The loss of ``benchmarks/loss_step.py`` (``SACLagLoss``, HalfCheetah sizes, 128x128, one cost:
four critics with targets), one thread, both updaters on the same loss, timed in interleaved
rounds of ``--calls`` calls; the median over rounds is reported.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from loss_step import ENVS, make_loss
from torchrl.objectives import SoftUpdate

from s3rl_torchrl.objectives import ForeachSoftUpdate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--out", type=Path, default=archive_path("target_update"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    loss = make_loss("sac_lag", *ENVS["halfcheetah"])
    updaters = {
        "SoftUpdate": SoftUpdate(loss, tau=0.05),
        "ForeachSoftUpdate": ForeachSoftUpdate(loss, tau=0.05),
    }
    times = interleaved_rounds(
        {name: updater.step for name, updater in updaters.items()},
        args.calls,
        args.rounds,
        warmup=100,
    )
    rows = {
        name: {"us_per_step": round(statistics.median(t), 1), "rounds": [round(x, 1) for x in t]}
        for name, t in times.items()
    }
    for name, row in rows.items():
        print(f"{name:18s} {row['us_per_step']:8.1f} us per step")
    write_report(args.out, {"results": rows})


if __name__ == "__main__":
    main()
