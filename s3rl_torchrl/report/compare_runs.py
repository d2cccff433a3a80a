"""Do two runs give the same metrics? ``s3rl-report compare-runs``: the largest relative
difference per ``metrics.csv`` column (timings left out) and of the final evaluation, e.g. of a
seeded run before and after a speed-up that should change nothing.

    s3rl-report compare-runs RUN_A RUN_B [--out same_metrics.json]
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from s3rl_torchrl.report.runs import ReportError

__all__ = ["TIMINGS", "compare_runs", "relative"]

# Columns whose name holds one of these are timings: they differ from run to run.
TIMINGS = ("seconds", "fps", "time")
FINAL_KEYS = ("reward_mean", "cost_mean", "safe_occupancy")


def relative(a: float, b: float) -> float:
    """``|a - b| / |a|`` (``|a|`` at least 1e-12); two NaNs are equal."""
    if math.isnan(a) and math.isnan(b):
        return 0.0
    return abs(a - b) / max(abs(a), 1e-12)


def compare_runs(a: str | Path, b: str | Path) -> dict:
    """The largest relative difference of every ``metrics.csv`` column of runs ``a`` and ``b``
    (epoch by epoch; timings and empty cells left out) and of their ``final_eval.json``.
    Raises :class:`ReportError` when the runs have different numbers of epochs."""
    a, b = Path(a), Path(b)
    rows = []
    for run in (a, b):
        with (run / "metrics.csv").open(newline="") as f:
            rows.append(list(csv.DictReader(f)))
    if len(rows[0]) != len(rows[1]):
        raise ReportError(f"different numbers of epochs: {len(rows[0])} and {len(rows[1])}")
    worst: dict[str, float] = {}
    for row_a, row_b in zip(*rows, strict=True):
        for key, value in row_a.items():
            if any(t in key for t in TIMINGS) or value in ("", None):
                continue
            worst[key] = max(worst.get(key, 0.0), relative(float(value), float(row_b[key])))
    finals = [json.loads((run / "final_eval.json").read_text()) for run in (a, b)]
    final = {key: relative(finals[0][key], finals[1][key]) for key in FINAL_KEYS}
    return {
        "runs": [str(a), str(b)],
        "epochs": len(rows[0]),
        "max_relative_difference_metrics_csv": max(worst.values(), default=0.0),
        "max_relative_difference_by_column": worst,
        "relative_difference_final_eval": final,
    }
