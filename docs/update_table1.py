"""Rewrite the two tables of docs/results.md's "Table 1 in full" from the committed runs.

    python docs/update_table1.py        # (make report runs it)

The rows of Table 1 in full (the paper's reward / cost beside ours, last policy and best-feasible
checkpoint, mean over seeds), the paired tests of the complete tasks (scipy's `ttest_rel` over
seeds, S3RL minus SAC-Lag) and rliable's aggregate over the complete tasks are recomputed from
the runs exported to results/safe_sound and results/table1 and from the paper's file; the prose
around them is left as written (it says what the numbers mean, so reread it after a change).
tests/docs/test_results_tables.py checks the doc against the same files on its own.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

from scipy.stats import ttest_rel

from s3rl_torchrl.report.paper import paper_results_for

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "results.md"
RESULTS = ROOT / "results"
ROOTS = ("safe_sound", "table1")
SECTION = "## Table 1 in full: sixteen tasks under `experiment=safe`"
TABLE_HEADER = "| task | algo | seeds | paper: reward / cost |"
PAIRED_HEADER = "| task | policy | reward (p) | cost (p) |"
ANSWER_HEADER = "| policy | P(S3RL's cost lower) | P(S3RL's reward higher) |"
ALGOS = {"S3RL": "s3rl", "SAC-Lag": "sac_lag"}
SEEDS = (10, 20, 30)
POLICIES = {"last": lambda final: final, "best-feasible": lambda final: final["best_feasible"]}


def runs(task: str, algo: str) -> dict[int, dict]:
    """seed -> final_eval.json of every exported run of (task, algo) in either tree."""
    found = {}
    for root in ROOTS:
        for seed in SEEDS:
            path = RESULTS / root / f"{algo}_{task}" / f"seed{seed}" / "final_eval.json"
            if path.exists():
                if seed in found:
                    raise SystemExit(f"{task} {algo} seed {seed} is exported to both trees")
                found[seed] = json.loads(path.read_text())
    return found


def paper(task: str, algo: str) -> str:
    values = {
        v.metric: v.mean
        for v in paper_results_for(task)
        if v.table == "Table 1" and v.algo == algo and v.metric in ("reward", "cost")
    }
    return f"{values['reward']:.2f} / {values['cost']:.2f}"


def ours(found: dict[int, dict], policy: str) -> str:
    if not found:
        return "pending"
    final = [POLICIES[policy](run) for run in found.values()]
    reward = statistics.mean(f["reward_mean"] for f in final)
    cost = statistics.mean(f["cost_mean"] for f in final)
    return f"{reward:.2f} / {cost:.2f}"


def paired(task: str, policy: str) -> str:
    s3rl, sac_lag = runs(task, "s3rl"), runs(task, "sac_lag")
    cells = []
    for key in ("reward_mean", "cost_mean"):
        a = [POLICIES[policy](s3rl[seed])[key] for seed in SEEDS]
        b = [POLICIES[policy](sac_lag[seed])[key] for seed in SEEDS]
        difference = statistics.mean(a) - statistics.mean(b)
        cells.append(f"{difference:+.2f} (p = {ttest_rel(a, b).pvalue:.2f})")
    return " | ".join(cells)


def answer(complete: list[str]) -> list[str]:
    """rliable's aggregate over the complete tasks' runs alone (the report's defaults: 2000
    resamples, seed 0), one row per protocol: the doc quotes it until all sixteen are in."""
    from s3rl_torchrl.report.aggregate import aggregate
    from s3rl_torchrl.report.runs import find_runs, group_runs

    groups = group_runs([run for root in ROOTS for run in find_runs(RESULTS / root)])
    result = aggregate([g for g in groups if g.task in set(complete)], "s3rl")
    rows = []
    for read in result.protocols:
        (pair,) = read.pairs
        s3rl, sac_lag = read.algos
        within = " / ".join("{} of {}".format(*row.within_count) for row in (s3rl, sac_lag))
        rows.append(
            f"| {read.protocol.replace('_', '-')} | {pair.cost.cell()} | {pair.reward.cell()} "
            f"| {within} | {s3rl.cost_ratio.cell()} / {sac_lag.cost_ratio.cell()} |"
        )
    return rows


def replace_table(text: str, header: str, rows: list[str]) -> str:
    """`text` with the rows of the table whose header starts with `header` replaced."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header)) + 2
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    return "\n".join(lines[:start] + rows + lines[end:]) + "\n"


def main() -> None:
    text = DOC.read_text()
    before, section = text.split(SECTION, 1)
    section, *after = section.split("\n## ", 1)
    # The rows keep the doc's task names and order (the paper's), read off the table itself.
    lines = section.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(TABLE_HEADER)) + 2
    tasks = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        tasks.append(line.split("|")[1].strip())
    tasks = list(dict.fromkeys(tasks))
    table, complete = [], []
    for task in tasks:
        for name, algo in ALGOS.items():
            found = runs(task, algo)
            table.append(
                f"| {task} | {name} | {len(found)} | {paper(task, algo)} "
                f"| {ours(found, 'last')} | {ours(found, 'best-feasible')} |"
            )
        if all(len(runs(task, algo)) == len(SEEDS) for algo in ALGOS.values()):
            complete.append(task)
    section = replace_table(section, TABLE_HEADER, table)
    paired_rows = [
        f"| {task} | {policy} | {paired(task, policy)} |"
        for task in complete
        for policy in POLICIES
    ]
    section = replace_table(section, PAIRED_HEADER, paired_rows)
    section = replace_table(section, ANSWER_HEADER, answer(complete))
    DOC.write_text(before + SECTION + "\n## ".join([section, *after]))
    print(f"{DOC}: {len(table)} rows, {len(complete)} complete tasks")


if __name__ == "__main__":
    main()
