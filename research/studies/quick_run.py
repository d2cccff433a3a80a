"""Does the first run a user makes (``make train``: ``s3rl-train`` on its defaults) keep its limit
whatever the seed and the floating-point rounding? Each seed and compile mode in a fresh process,
as a user runs it; the last policy's final evaluation and the wall time of each run.

    python research/studies/quick_run.py [--seeds 1 2 3 4 5] [--compile true false]
        [--out benchmarks/results/archive/<date>/quick_run.json] [-- extra s3rl-train overrides]

Extra overrides after ``--`` go to every run (to try a setting before it becomes the default).
The JSON has one record per run: seed, compile, the final evaluation (reward, cost and their
std over the 10 episodes), whether the cost is within the limit, the training frames and the
wall time of the whole command (set-up, compilation, training, evaluation). Not a timing test:
the wall times are only comparable between runs of one invocation on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
from _report import archive_path, write_report

TRAIN = str(Path(sys.executable).with_name("s3rl-train"))


def run(seed: int, compiled: bool, extra: list[str], keep: Path | None = None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp) / "run"
        if keep is not None:
            run_dir = keep / f"seed{seed}_compile{str(compiled).lower()}"
        command = [
            TRAIN,
            f"seed={seed}",
            f"compile={str(compiled).lower()}",
            "logger.progress_bar=false",
            f"hydra.run.dir={run_dir}",
            *extra,
        ]
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
        final = json.loads((run_dir / "final_eval.json").read_text())
        config = json.loads((run_dir / "config.json").read_text())
    limit = config["task"]["cost_limit"]
    return {
        "seed": seed,
        "compile": compiled,
        "task": config["task"]["name"],
        "algo": config["algo"]["name"],
        "frames": config["collector"]["total_frames"],
        "reward": final["reward_mean"],
        "reward_std": final["reward_std"],
        "cost": final["cost_mean"],
        "cost_std": final["cost_std"],
        "cost_limit": limit,
        "within_limit": final["cost_mean"] <= limit,
        "wall_seconds": round(seconds, 1),
    }


def main() -> None:
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    parser.add_argument("--compile", nargs="+", default=["true", "false"])
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep each run's directory under this one (default: discard them)")
    parser.add_argument("--out", type=Path, default=archive_path("quick_run"))
    args = parser.parse_args(argv)
    records = []
    for compiled in (c == "true" for c in args.compile):
        for seed in args.seeds:
            record = run(seed, compiled, extra, args.keep)
            records.append(record)
            print(
                f"seed {seed} compile={compiled}: reward {record['reward']:.1f}, cost "
                f"{record['cost']:.2f} (limit {record['cost_limit']:g}), "
                f"{record['wall_seconds']:.0f} s",
                flush=True,
            )
    within = sum(r["within_limit"] for r in records)
    print(f"{within} of {len(records)} runs within the limit")
    write_report(args.out, {"extra_overrides": extra, "runs": records})


if __name__ == "__main__":
    main()
