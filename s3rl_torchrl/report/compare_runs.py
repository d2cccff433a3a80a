"""Do two runs give the same metrics? Largest relative difference per metrics.csv column
(timings left out) and of the final evaluation, e.g. a seeded run before and after a speed-up.

    python benchmarks/compare_runs.py <run dir A> <run dir B> [--out results/<name>.json]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

from _report import write_report

TIMINGS = ("seconds", "fps", "time")


def relative(a: float, b: float) -> float:
    if math.isnan(a) and math.isnan(b):
        return 0.0
    return abs(a - b) / max(abs(a), 1e-12)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=Path)
    parser.add_argument("b", type=Path)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    rows = [list(csv.DictReader((run / "metrics.csv").open())) for run in (args.a, args.b)]
    if len(rows[0]) != len(rows[1]):
        raise SystemExit(f"different numbers of epochs: {len(rows[0])} and {len(rows[1])}")
    worst: dict[str, float] = {}
    for row_a, row_b in zip(*rows, strict=True):
        for key, value in row_a.items():
            if any(t in key for t in TIMINGS) or value in ("", None):
                continue
            worst[key] = max(worst.get(key, 0.0), relative(float(value), float(row_b[key])))
    finals = [json.loads((run / "final_eval.json").read_text()) for run in (args.a, args.b)]
    final = {key: relative(finals[0][key], finals[1][key])
             for key in ("reward_mean", "cost_mean", "safe_occupancy")}
    summary = {
        "runs": [str(args.a), str(args.b)],
        "epochs": len(rows[0]),
        "max_relative_difference_metrics_csv": max(worst.values()),
        "max_relative_difference_by_column": worst,
        "relative_difference_final_eval": final,
    }
    print(json.dumps({k: v for k, v in summary.items() if k != "max_relative_difference_by_column"}))
    if args.out:
        write_report(args.out, summary)


if __name__ == "__main__":
    main()
