"""The per-task evidence tables of docs/results.md ("The evidence (seeds 10, 20, 30, 1M frames)")
say what the committed runs in results/safe_sound say.

Those tables are written by hand, beside the text that reads them; this test recomputes every
number in them from each run's `final_eval.json` and `metrics.csv` (the columns' definitions
are the ones docs/results.md gives), so that a copied or stale number fails here.
"""

from __future__ import annotations

import csv
import json
import re
import statistics
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "results.md"
RESULTS = ROOT / "results" / "safe_sound"
ALGOS = {"S3RL": "s3rl", "SAC-Lag": "sac_lag"}
SEEDS = (10, 20, 30)
HEADER = (
    "| algo | policy | reward (mean ± std over seeds) | cost | reward per seed (10 / 20 / 30) |"
)


def evidence_tables() -> dict[str, list[list[str]]]:
    """task -> the cells of each row of its table, from the evidence section of the doc."""
    text = DOC.read_text()
    section = text.split("### The evidence (seeds 10, 20, 30, 1M frames)", 1)[1]
    section = section.split("\n#### ", 1)[0]
    tables: dict[str, list[list[str]]] = {}
    for block in re.split(r"\n(?=\*\*Safety)", section)[1:]:
        task = re.match(r"\*\*(Safety\w+-v\d)", block).group(1)
        lines = block.splitlines()
        if not any(line.startswith(HEADER) for line in lines):
            continue
        start = next(i for i, line in enumerate(lines) if line.startswith(HEADER)) + 2
        rows = []
        for line in lines[start:]:
            if not line.startswith("|"):
                break
            rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        tables[task] = rows
    return tables


def close(written: str, value: float) -> bool:
    """`written` is `value` rounded to the digits it shows (half a unit of its last digit)."""
    decimals = len(written.split(".")[1]) if "." in written else 0
    return abs(float(written) - value) <= 0.5 * 10**-decimals + 1e-9


def numbers(cell: str) -> list[str]:
    return re.findall(r"-?\d+(?:\.\d+)?", cell)


def run_stats(task: str, algo: str, seed: int) -> dict:
    """The table's columns for one run, computed from its files."""
    run = RESULTS / f"{algo}_{task}" / f"seed{seed}"
    final = json.loads((run / "final_eval.json").read_text())
    limit = json.loads((run / "config.json").read_text())["task"]["cost_limit"]
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    lam = [float(r["lagrangian"]) for r in rows]
    peak = max(range(len(lam)), key=lam.__getitem__)
    half = rows[len(rows) // 2 :]
    tail = rows[int(len(rows) * 0.8) :]
    mean = lambda key, rs: statistics.mean(float(r[key]) for r in rs)  # noqa: E731
    return {
        "reward": final["reward_mean"],
        "cost": final["cost_mean"],
        "best_reward": final["best_feasible"]["reward_mean"],
        "best_cost": final["best_feasible"]["cost_mean"],
        "lambda_peak": lam[peak],
        "lambda_peak_k": int(rows[peak]["frames"]) // 1000,
        "lambda_end": lam[-1],
        "over": 100 * sum(float(r["eval/cost"]) > limit for r in half) / len(half),
        "last20": (mean("eval/reward", tail), mean("eval/cost", tail), mean("train/cost", tail)),
    }


TABLES = evidence_tables()


def test_the_evidence_section_has_its_tables():
    # The complete tasks at the time of writing; more may be added, none may vanish.
    expected = {
        "SafetyBallRun-v0",
        "SafetyCarRun-v0",
        "SafetyDroneRun-v0",
        "SafetyBallCircle-v0",
        "SafetyHalfCheetahVelocity-v1",
        "SafetyPointGoal1-v0",
    }
    assert expected <= set(TABLES)


@pytest.mark.parametrize("task", sorted(TABLES))
def test_evidence_table_matches_the_committed_runs(task):
    rows = TABLES[task]
    assert [(r[0], r[1]) for r in rows] == [
        ("S3RL", "last"),
        ("S3RL", "best-feasible"),
        ("SAC-Lag", "last"),
        ("SAC-Lag", "best-feasible"),
    ]
    for last, best in (rows[0:2], rows[2:4]):
        algo = ALGOS[last[0]]
        runs = [run_stats(task, algo, seed) for seed in SEEDS]
        where = f"{task} {last[0]}"
        for row, reward_key, cost_key in (
            (last, "reward", "cost"),
            (best, "best_reward", "best_cost"),
        ):
            for cell, key in ((row[2], reward_key), (row[3], cost_key)):
                values = [run[key] for run in runs]
                mean, std = numbers(cell)
                assert close(mean, statistics.mean(values)), f"{where} {row[1]} {key} mean: {cell}"
                assert close(std, statistics.stdev(values)), f"{where} {row[1]} {key} std: {cell}"
        for cell, key in ((last[4], "reward"), (last[5], "cost")):
            written = numbers(cell)
            assert len(written) == 3, f"{where}: {cell}"
            for w, run in zip(written, runs):
                assert close(w, run[key]), f"{where} {key} per seed: {cell}"
        lambdas = numbers(last[6])
        assert len(lambdas) == 9, f"{where}: {last[6]}"
        for i, run in enumerate(runs):
            assert close(lambdas[2 * i], run["lambda_peak"]), f"{where} lambda peak: {last[6]}"
            assert int(lambdas[2 * i + 1]) == run["lambda_peak_k"], (
                f"{where} peak frames: {last[6]}"
            )
            assert close(lambdas[6 + i], run["lambda_end"]), f"{where} lambda end: {last[6]}"
        for w, run in zip(numbers(last[7]), runs, strict=True):
            assert close(w, run["over"]), f"{where} second half over the limit: {last[7]}"
        last20 = numbers(last[8])
        assert len(last20) == 9, f"{where}: {last[8]}"
        for i, run in enumerate(runs):
            for j in range(3):
                assert close(last20[3 * i + j], run["last20"][j]), f"{where} last 20%: {last[8]}"
