"""The selection table of the delivered-policy controller: one row per run of
`selection.py`, read from its exported files (config.json, metrics.csv, final_eval.json).

    python research/delivered_policy/summarise.py research/results/delivered_selection \
        --out research/delivered_policy/selection.md

Per run: the candidate (the directory below the root), the last policy's and the delivered
pick's final evaluation (reward / cost, 10 episodes), the training cost and the share of epochs
whose 2-episode evaluation was over the limit, both over the last 20% of the run's frames, and
lambda's mean there. Unfinished runs are listed with the frames they reached.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.runs import find_runs


def tail(run, column: str, share: float = 0.2) -> np.ndarray:
    frames, values = run.column(column)
    start = (1 - share) * run.total_frames
    return np.array([v for f, v in zip(frames, values) if f > start], dtype=float)


def rows(root: Path) -> list[list[str]]:
    table = []
    for run in find_runs(root):
        candidate = run.path.relative_to(root).parts[0]
        limit = run.cost_limit
        train_cost = tail(run, "train/cost")
        eval_cost = tail(run, "eval/cost")
        lam = tail(run, "lagrangian")
        if run.finished:
            last = f"{run.final['reward_mean']:.1f} / {run.final['cost_mean']:.1f}"
            picked = run.final.get("delivered")
            delivered = "–" if picked is None else (
                f"{picked['reward_mean']:.1f} / {picked['cost_mean']:.1f} (epoch {picked['epoch']})"
            )
        else:
            last = delivered = f"running ({run.frames // 1000}k of {run.total_frames // 1000}k)"
        table.append([
            candidate, run.algo, run.task, str(run.seed), f"{limit:g}", last, delivered,
            f"{np.nanmean(train_cost):.1f}" if train_cost.size else "–",
            f"{np.mean(eval_cost > limit):.2f}" if eval_cost.size else "–",
            f"{np.nanmean(lam):.3f}" if lam.size else "–",
        ])
    return sorted(table, key=lambda r: (r[2], r[1], int(r[3]), r[0]))


HEADER = ["candidate", "algo", "task", "seed", "limit", "last policy: reward / cost",
          "delivered pick: reward / cost", "train cost, last 20%",
          "epochs over the limit, last 20%", "lambda, last 20%"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(row) + " |" for row in rows(args.root)]
    text = "\n".join(lines) + "\n"
    if args.out is None:
        print(text)
    else:
        args.out.write_text(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
