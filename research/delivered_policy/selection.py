"""The selection runs of the delivered-policy controller (issue 60), as one resumable queue.

Each entry is one `s3rl-train` run under `experiment=safe` at 1M frames, seeds 1 and 2 only
(the reported seeds are 10, 20 and 30), in `<out>/<candidate>/<algo>_<task>/seed<N>`. Run again
after an interruption, the same command resumes every unfinished run (`resume=auto`) and skips
the finished ones (`final_eval.json`). Two runs at a time, one thread each (2 cores):

    python research/delivered_policy/selection.py --out /work/runs/delivered_selection

Candidates (algo.* keys, objectives/lagrangian.py):
- margin: lagrangian_target=0.7 (J, the training episodes' cost, held at 7 of a limit of 10);
- aim: lagrangian_target=0.8 and lagrangian_eval_window=6 (J is the larger of the training
  cost and the last 6 deterministic evaluation episodes' mean: 3 epochs of 2 episodes).
"""

from __future__ import annotations

import argparse
import itertools
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

CANDIDATES = {
    "margin": ["algo.lagrangian_target=0.7"],
    "aim": ["algo.lagrangian_target=0.8", "algo.lagrangian_eval_window=6"],
}
# The tasks whose delivered policy missed the limit in results/table1 + results/safe_sound,
# worst first.
TASKS = [
    "SafetyPointCircle1-v0",
    "SafetySwimmerVelocity-v1",
    "SafetyCarCircle-v0",
    "SafetyAntVelocity-v1",
    "SafetyWalker2dVelocity-v1",
    "SafetyBallRun-v0",
]
ALGOS = ["sac_lag", "s3rl"]
SEEDS = [1, 2]


def jobs(out: Path):
    for seed, task, algo, (name, overrides) in itertools.product(
        SEEDS, TASKS, ALGOS, CANDIDATES.items()
    ):
        run_dir = out / name / f"{algo}_{task}" / f"seed{seed}"
        yield run_dir, [
            "experiment=safe",
            f"task={task}",
            f"algo={algo}",
            f"seed={seed}",
            *overrides,
            "threads=1",
            "save_interval=2",
            "logger.progress_bar=false",
            "resume=auto",
            f"hydra.run.dir={run_dir}",
        ]


def run(job) -> str:
    run_dir, overrides = job
    if (run_dir / "final_eval.json").exists():
        return f"done already: {run_dir}"
    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir.parent / f"{run_dir.name}.log", "a") as log:
        code = subprocess.call(
            [sys.executable, "-m", "s3rl_torchrl.recipes.train", *overrides],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=os.environ,
        )
    return f"exit {code}: {run_dir}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    with ThreadPoolExecutor(args.workers) as pool:
        for line in pool.map(run, jobs(args.out)):
            print(line, flush=True)


if __name__ == "__main__":
    main()
