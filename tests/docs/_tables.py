"""Reading the tables of a markdown page, and the committed runs they quote (tests/docs and
tests/research share these)."""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "results"
RESEARCH_RESULTS = ROOT / "research" / "results"
ALGOS = {"S3RL": "s3rl", "SAC-Lag": "sac_lag"}
SEEDS = (10, 20, 30)
# Table 1 under experiment=safe: the evidence's seven tasks and sweep=table1's nine.
TABLE1_ROOTS = ("safe_sound", "table1")


def table_rows(text: str, header: str) -> list[list[str]]:
    """The cells of each row of the first table in `text` whose header starts with `header`."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header)) + 2
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def close(written: str, value: float) -> bool:
    """`written` is `value` rounded to the digits it shows (half a unit of its last digit)."""
    decimals = len(written.split(".")[1]) if "." in written else 0
    return abs(float(written) - value) <= 0.5 * 10**-decimals + 1e-9


def numbers(cell: str) -> list[str]:
    return re.findall(r"-?\d+(?:\.\d+)?", cell)


def table1_runs(task: str, algo: str) -> dict[int, dict]:
    """seed -> final_eval.json of every exported run of (task, algo) in either tree."""
    found = {}
    for root in TABLE1_ROOTS:
        for seed in SEEDS:
            path = RESULTS / root / f"{algo}_{task}" / f"seed{seed}" / "final_eval.json"
            if path.exists():
                assert seed not in found, f"{task} {algo} seed {seed} is in both trees"
                found[seed] = json.loads(path.read_text())
    return found


def complete_tasks(table1: list[list[str]]) -> list[str]:
    """The tasks of a Table 1 (its rows: task, algo, ...) whose both algos have every seed
    exported, in its order."""
    return [
        row[0]
        for row in table1
        if row[1] == "S3RL"
        and all(len(table1_runs(row[0], algo)) == len(SEEDS) for algo in ("s3rl", "sac_lag"))
    ]


def pair_wins(task: str, policy, key: str, sign: float) -> float:
    """The share of a task's 9 pairs of runs (S3RL seed, SAC-Lag seed) in which S3RL's is
    better, a tie one half, counted from the runs' final_eval.json."""
    ours = [sign * policy(r)[key] for r in table1_runs(task, "s3rl").values()]
    theirs = [sign * policy(r)[key] for r in table1_runs(task, "sac_lag").values()]
    pairs = [(a > b) + 0.5 * (a == b) for a in ours for b in theirs]
    return sum(pairs) / len(pairs)


def load_update_table1():
    """docs/update_table1.py (make report runs it; not a package module) as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "update_table1", ROOT / "docs" / "update_table1.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
