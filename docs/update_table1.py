"""Rewrite the Table 1 tables of docs/results.md (and of the research notes that read the same
runs) from the committed runs.

    python docs/update_table1.py               # docs/results.md (make report runs it)
    python docs/update_table1.py --research    # the research notes (make research-report)

docs/results.md: the rows of Table 1 (the paper's reward / cost beside ours, last policy and
best-feasible checkpoint, mean over seeds), rliable's aggregate over the complete tasks, each of
its probabilities without the task that lowers it most and the one that raises it most, and the
counts of its cost profiles, recomputed from the runs exported to results/safe_sound and
results/table1 and from the paper's file; the paper-settings runs of results/reproduction beside
the paper's rows, `s3rl-report gap`'s answer per preset on their tasks, and the delivered-policy
evidence (results/table1_v2) against its targets, from `s3rl-report before-after`'s pages.

The research notes (research/2026-11-28-table1-readings.md,
research/2026-11-28-contrastive-phase-probe.md): the same tables and the status line, each seed's
last policy, the paired tests of the complete tasks (scipy's `ttest_rel` over seeds, S3RL minus
SAC-Lag), the probabilities of improvement task by task, and the two tables of the
contrastive-phase probe from research/results/phase_probe.

The prose around the tables is left as written (it says what the numbers mean, so reread it after
a change). tests/docs/test_results_tables.py and tests/research/test_research_tables.py check the
pages against the same files on their own.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
from pathlib import Path

from scipy.stats import ttest_rel

from s3rl_torchrl.report.aggregate import (
    Aggregate,
    Estimate,
    aggregate,
    probability_of_improvement,
    run_scores,
)
from s3rl_torchrl.report.before_after import MISS_CAUSES, TARGET_KINDS
from s3rl_torchrl.report.gap import format_difference
from s3rl_torchrl.report.paper import paper_results_for
from s3rl_torchrl.report.runs import Run, RunGroup, find_runs, group_runs
from s3rl_torchrl.report.stats import paired_seed_test

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "results.md"
READINGS = ROOT / "research" / "2026-11-28-table1-readings.md"
PROBE_NOTE = ROOT / "research" / "2026-11-28-contrastive-phase-probe.md"
RESULTS = ROOT / "results"
ROOTS = ("safe_sound", "table1")
TABLE_HEADER = "| task | algo | seeds | paper: reward / cost |"
PAIRED_HEADER = "| task | policy | reward (p) | cost (p) |"
PER_SEED_HEADER = "| task | algo | seed 10: reward / cost |"
ANSWER_HEADER = "| policy | P(S3RL's cost lower) | P(S3RL's reward higher) |"
PER_TASK_HEADER = "| task | last: P(cost lower) |"
WITHOUT_ONE_TASK_HEADER = "| reading | every complete task |"
PROFILE_HEADER = "| policy | algo | cost / limit: 0 |"
# The cost / limit thresholds the profile counts are read at: zero cost, a fifth and half of the
# limit, the limit (the share within it), twice the limit.
PROFILE_THRESHOLDS = (0.0, 0.2, 0.5, 1.0, 2.0)
# The probe of where in its interval a contrastive phase falls (results/phase_probe): one run
# continued past 1M with a longer interval, and finished runs continued 1000 gradient steps.
PROBE = ROOT / "research" / "results" / "phase_probe"
PHASE_OFFSET_HEADER = "| frames | gradient steps since the last phase |"
PHASE_PROBE_HEADER = "| task | algo | seed | at 1M: reward / cost |"
# experiment=paper's runs (results/reproduction): each (task, algo) with every seed finished.
REPRODUCTION = RESULTS / "reproduction"
REPRODUCTION_HEADER = "| task | S3RL: reward / cost | SAC-Lag: reward / cost |"
# S3RL against SAC-Lag per preset on the reproduction's tasks: `s3rl-report gap`'s answers
# (docs/reproduction/gap_<protocol>.json, written by make report before this script runs).
# A setting's *delivered* answer is its last policy's where its runs pick nothing, so it is shown
# only for a setting whose runs made a pick.
GAP_PAGES = {policy: ROOT / "docs" / "reproduction" / f"gap_{policy.replace('-', '_')}.json"
             for policy in ("last", "best-feasible", "delivered")}
GAP_HEADER = "| setting | policy | tasks | P(S3RL's cost lower) | P(S3RL's reward higher) |"
# Issue 60's evidence against its targets: `s3rl-report before-after`'s targets for the last
# policy and the delivered pick (docs/table1_v2/before_after_<protocol>.json, written by make
# report before this script runs), over the runs exported to results/table1_v2 so far.
BEFORE_AFTER_PAGES = {"last": ROOT / "docs" / "table1_v2" / "before_after_last.json",
                      "delivered": ROOT / "docs" / "table1_v2" / "before_after_delivered.json"}
EVIDENCE_HEADER = "| algo | target | before: Table 1's runs | last policy | delivered pick |"
STATUS = "**Where it stands: "
ALGOS = {"S3RL": "s3rl", "SAC-Lag": "sac_lag"}
SEEDS = (10, 20, 30)
POLICIES = {"last": lambda final: final, "best-feasible": lambda final: final["best_feasible"]}


def exported_runs() -> dict[str, list[Run]]:
    """Every run exported to each tree, read once with the report's own reader."""
    return {root: find_runs(RESULTS / root) for root in ROOTS}


def status(tasks: list[str], complete: list[str], runs: dict[str, list[Run]]) -> str:
    """The section's status line. `sweep=table1` runs every task the evidence
    (results/safe_sound) does not, both algos, every seed."""
    evidence = {run.task for run in runs["safe_sound"]}
    planned = len(ALGOS) * len(SEEDS) * len([task for task in tasks if task not in evidence])
    exported = sum(run.finished for run in runs["table1"])
    return (
        f"{STATUS}{len(complete)} of {len(tasks)} tasks are complete; {exported} of the "
        f"{planned} `sweep=table1` runs are exported.**"
    )


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


def per_seed(found: dict[int, dict]) -> str:
    """Each seed's last policy (its mean over the final episodes), "pending" where not run."""
    return " | ".join(
        f"{found[seed]['reward_mean']:.1f} / {found[seed]['cost_mean']:.1f}"
        if seed in found
        else "pending"
        for seed in SEEDS
    )


def paired(s3rl: dict[int, dict], sac_lag: dict[int, dict], policy: str) -> str:
    cells = []
    for key in ("reward_mean", "cost_mean"):
        a = [POLICIES[policy](s3rl[seed])[key] for seed in SEEDS]
        b = [POLICIES[policy](sac_lag[seed])[key] for seed in SEEDS]
        difference = statistics.mean(a) - statistics.mean(b)
        p = ttest_rel(a, b).pvalue
        # Identical differences on every seed (all zero costs, say) leave the test undefined.
        cells.append(f"{difference:+.2f} (p " + ("undefined)" if math.isnan(p) else f"= {p:.2f})"))
    return " | ".join(cells)


def reproduction_rows(tasks: list[str]) -> list[str]:
    """The paper-settings runs beside the paper's Table 1, in `tasks`' order, one row per task
    whose seeds have all finished for both algos: each algo's last policy (mean over seeds of
    its final evaluation), the paper's rows, and S3RL's cost minus SAC-Lag's, paired by seed."""
    finals: dict[tuple[str, str], dict[int, dict]] = {}
    for run in find_runs(REPRODUCTION):
        if run.finished:
            finals.setdefault((run.task, run.algo), {})[run.seed] = run.final
    rows = []
    for task in tasks:
        found = {algo: finals.get((task, algo), {}) for algo in ALGOS.values()}
        if any(sorted(runs) != list(SEEDS) for runs in found.values()):
            continue
        costs = {algo: {seed: final["cost_mean"] for seed, final in runs.items()}
                 for algo, runs in found.items()}
        difference = format_difference(paired_seed_test(costs["s3rl"], costs["sac_lag"]))
        cells = [ours(found[algo], "last") for algo in ALGOS.values()]
        cells += [paper(task, algo) for algo in ALGOS.values()]
        rows.append(f"| {task} | " + " | ".join(cells) + f" | {difference} |")
    return rows


def gap_rows() -> list[str]:
    """Per setting and protocol, the gap page's answer: rliable's probabilities over the tasks
    both it and the first setting (the paper's) have both algos of (their number), with their
    bootstrap intervals."""
    pages = {policy: json.loads(path.read_text()) for policy, path in GAP_PAGES.items()}
    rows = []
    for setting, trees in pages["last"]["settings"].items():
        # Read from the configs alone: whether a run picked needs none of its metrics.
        picks = any(json.loads(config.read_text()).get("eval", {}).get("delivery_epochs")
                    for tree in trees for config in (ROOT / tree).glob("*/seed*/config.json"))
        for policy, page in pages.items():
            if policy == "delivered" and not picks:
                continue
            for read in page["answers"]:
                if read["setting"] != setting:
                    continue
                cells = [Estimate(**read[key]).cell() for key in ("lower_cost", "higher_reward")]
                rows.append(f"| {setting} | {policy} | {len(read['tasks'])} | "
                            + " | ".join(cells) + " |")
    return rows


#: The evidence table's last rows: each algo's runs over the limit, counted by MISS_CAUSES.
MISSES_LABEL = "runs over the limit, by what their files show"


def evidence_rows() -> list[str]:
    """Per target kind and algo (and task, for a task's own target), its value under each
    protocol as the before/after page gives it, beside the same seeds' Table 1 runs (the
    'before' side, which delivered its last policy); the reward-kept targets, one per task, as
    the count of tasks that met theirs; last, each algo's misses counted by their cause."""
    pages = {protocol: json.loads(path.read_text()) for protocol, path in BEFORE_AFTER_PAGES.items()}
    before = pages["last"]
    rows = []
    for kind, label in TARGET_KINDS.items():
        for name, algo in ALGOS.items():
            found = {protocol: [t for t in page["targets"] if t["kind"] == kind and t["algo"] == algo]
                     for protocol, page in pages.items()}
            paired = [r for r in before["rows"] if r["algo"] == algo]
            total = sum(len(r["pairs"]) for r in paired)
            if kind == "reward_kept":
                cells = [
                    f"{sum(t['met'] for t in mine)} of {len(mine)} tasks "
                    f"(each target >= {mine[0]['least']:.2f})"
                    if mine else "–"
                    for mine in found.values()
                ]
                rows.append(f"| {name} | {label} | – | " + " | ".join(cells) + " |")
                continue
            for task in dict.fromkeys(t["task"] for mine in found.values() for t in mine):
                if kind == "within":
                    old = f"{sum(r['within_before'] for r in paired)} of {total}"
                elif kind == "moving":
                    stopped = sum(s["algo"] == algo and s["side"] == "before" for s in before["stops"])
                    old = f"{total - stopped} of {total}"
                else:
                    (row,) = [r for r in paired if r["task"] == task]
                    old = " / ".join(f"{statistics.fmean(p[f'before_{key}'] for p in row['pairs']):.2f}"
                                     for key in ("reward", "cost"))
                cells = [next((t["value"] for t in mine if t["task"] == task), "–")
                         for mine in found.values()]
                shown = f"{task}: {label}" if task else label
                rows.append(f"| {name} | {shown} | {old} | " + " | ".join(cells) + " |")
    for name, algo in ALGOS.items():
        cells = []
        for page in pages.values():
            causes = [m["cause"] for m in page["misses"] if m["algo"] == algo]
            cells.append(", ".join(f"{causes.count(cause)} {label}" for cause, label
                                   in MISS_CAUSES.items() if cause in causes) or "none")
        rows.append(f"| {name} | {MISSES_LABEL} | – | " + " | ".join(cells) + " |")
    return rows


def answer(result: Aggregate) -> list[str]:
    """rliable's aggregate (over the complete tasks' runs alone, the report's defaults: 2000
    resamples, seed 0), one row per protocol: the doc quotes it until all sixteen are in."""
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


def per_task(result: Aggregate) -> list[str]:
    """Where the answer's probabilities come from: per complete task and protocol, the share of
    the 9 pairs of runs (S3RL seed, SAC-Lag seed) in which S3RL's costs less and earns more
    (ties one half); the last row is their mean over the tasks, the answer's point estimate."""
    pairs = {read.protocol: read.pairs[0] for read in result.protocols}
    columns = [(pair.cost_by_task, pair.reward_by_task) for pair in pairs.values()]
    rows = [
        f"| {task} | "
        + " | ".join(f"{by_task[task]:.2f}" for both in columns for by_task in both)
        + " |"
        for task in next(iter(pairs.values())).tasks
    ]
    means = [estimate.point for pair in pairs.values() for estimate in (pair.cost, pair.reward)]
    rows.append("| mean over the tasks | " + " | ".join(f"{m:.2f}" for m in means) + " |")
    return rows


def without_one_task(result: Aggregate, groups: list[RunGroup]) -> list[str]:
    """How far a single task moves the answer: each probability of improvement over every
    complete task, then without the task whose removal lowers it most and without the one whose
    removal raises it most (the mean of the other tasks' per-task values decides; the first in
    task order on a tie), each with the interval of rliable's bootstrap over the tasks left."""
    rows = []
    for read in result.protocols:
        (pair,) = read.pairs
        scores = run_scores(groups, read.protocol)
        first, second = scores[pair.first], scores[pair.second]
        readings = (
            ("cost lower", "cost", pair.cost, pair.cost_by_task, True),
            ("reward higher", "reward", pair.reward, pair.reward_by_task, False),
        )
        for name, key, estimate, by_task, lower_is_better in readings:
            without = {
                task: statistics.mean(p for other, p in by_task.items() if other != task)
                for task in by_task
            }
            cells = [estimate.cell()]
            for pick in (min, max):
                left_out = pick(without, key=without.get)
                left, _ = probability_of_improvement(
                    *({t: getattr(s, key) for t, s in run.items() if t != left_out}
                      for run in (first, second)),
                    lower_is_better=lower_is_better, reps=result.reps, seed=result.seed,
                )
                cells.append(f"{left.cell()} without {left_out}")
            protocol = read.protocol.replace("_", "-")
            rows.append(f"| {protocol}: P(S3RL's {name}) | " + " | ".join(cells) + " |")
    return rows


def profile_counts(result: Aggregate) -> list[str]:
    """The cost profiles of the same runs as counts: per protocol and algo, how many runs have
    cost / limit at or below each threshold (the figure's right column, read at a few points)."""
    names = {algo: name for name, algo in ALGOS.items()}
    rows = []
    for read in result.protocols:
        for row in read.algos:
            _, ratio = read.profile_data[row.label]
            pooled = [float(value) for values in ratio.values() for value in values]
            cells = [
                f"{sum(value <= threshold for value in pooled)} of {len(pooled)}"
                for threshold in PROFILE_THRESHOLDS
            ]
            protocol = read.protocol.replace("_", "-")
            rows.append(f"| {protocol} | {names[row.label]} | " + " | ".join(cells) + " |")
    return rows


def phase_offset_rows() -> list[str]:
    """Each epoch past 1M of the run continued with a longer contrastive interval: how many
    gradient steps it ended after the last phase, its evaluation and its training episodes."""
    (run,) = (PROBE / "interval1500").glob("*/seed*")
    interval = json.loads((run / "config.json").read_text())["algo"]["contrastive_cfg"][
        "update_interval"
    ]
    with (run / "metrics.csv").open() as f:
        rows = [row for row in csv.DictReader(f) if int(row["frames"]) > 1_000_000]
    return [
        f"| {row['frames']} | {int(row['grad_steps']) % interval} "
        f"| {float(row['eval/reward']):.1f} / {float(row['eval/cost']):.1f} "
        f"| {float(row['train/reward']):.1f} / {float(row['train/cost']):.1f} |"
        for row in rows
    ]


def phase_probe_rows(tasks: list[str], finals: dict[tuple[str, str], dict[int, dict]]) -> list[str]:
    """Each probed run's last policy at 1M (`finals`, its Table 1 export as main reads it)
    beside the same run 1000 gradient steps later, in Table 1's task order, S3RL first, seeds
    ascending."""
    rows = []
    for task in tasks:
        for name, algo in ALGOS.items():
            for seed in SEEDS:
                later = PROBE / "after1000" / f"{algo}_{task}" / f"seed{seed}" / "final_eval.json"
                if not later.exists():
                    continue
                cells = [
                    f"{final['reward_mean']:.1f} / {final['cost_mean']:.1f}"
                    for final in (finals[task, algo][seed], json.loads(later.read_text()))
                ]
                rows.append(f"| {task} | {name} | {seed} | " + " | ".join(cells) + " |")
    return rows


def table_body(lines: list[str], header: str) -> tuple[int, int]:
    """Where the rows of the table whose header starts with `header` begin and end."""
    start = next(i for i, line in enumerate(lines) if line.startswith(header)) + 2
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    return start, end


def table_rows(tasks: list[str]) -> dict[str, list[str]]:
    """Every table this script writes, by its header, for Table 1's tasks in `tasks`' order."""
    runs = exported_runs()
    # One grouping of both trees: group_runs refuses a seed exported to both.
    groups = group_runs([run for found in runs.values() for run in found])
    finals = {(g.task, g.algo): {run.seed: run.final for run in g.finished} for g in groups}
    for task in tasks:
        for algo in ALGOS.values():
            finals.setdefault((task, algo), {})
    complete = [
        task
        for task in tasks
        if all(sorted(finals[task, algo]) == list(SEEDS) for algo in ALGOS.values())
    ]
    complete_groups = [g for g in groups if g.task in set(complete)]
    result = aggregate(complete_groups, "s3rl")
    return {
        STATUS: [status(tasks, complete, runs)],
        TABLE_HEADER: [
            f"| {task} | {name} | {len(finals[task, algo])} | {paper(task, algo)} "
            f"| {ours(finals[task, algo], 'last')} | {ours(finals[task, algo], 'best-feasible')} |"
            for task in tasks
            for name, algo in ALGOS.items()
        ],
        PAIRED_HEADER: [
            f"| {task} | {policy} | {paired(finals[task, 's3rl'], finals[task, 'sac_lag'], policy)} |"
            for task in complete
            for policy in POLICIES
        ],
        PER_SEED_HEADER: [
            f"| {task} | {name} | {per_seed(finals[task, algo])} |"
            for task in tasks
            for name, algo in ALGOS.items()
            if any(finals[task, a] for a in ALGOS.values())
        ],
        ANSWER_HEADER: answer(result),
        PER_TASK_HEADER: per_task(result),
        WITHOUT_ONE_TASK_HEADER: without_one_task(result, complete_groups),
        PROFILE_HEADER: profile_counts(result),
        PHASE_OFFSET_HEADER: phase_offset_rows(),
        PHASE_PROBE_HEADER: phase_probe_rows(tasks, finals),
        REPRODUCTION_HEADER: reproduction_rows(tasks),
        GAP_HEADER: gap_rows(),
        EVIDENCE_HEADER: evidence_rows(),
    }


def rewrite(text: str, tables: dict[str, list[str]]) -> str:
    """`text` with every table whose header it has (and its status line) rewritten."""
    lines = text.split("\n")
    for header, rows in tables.items():
        if header == STATUS:
            lines = [rows[0] if line.startswith(STATUS) else line for line in lines]
        elif any(line.startswith(header) for line in lines):
            start, end = table_body(lines, header)
            lines = lines[:start] + rows + lines[end:]
    return "\n".join(lines)


def document_tasks(doc: Path) -> list[str]:
    """Table 1's tasks in the order of the page's own table (the paper's)."""
    lines = doc.read_text().splitlines()
    start, end = table_body(lines, TABLE_HEADER)
    return list(dict.fromkeys(line.split("|")[1].strip() for line in lines[start:end]))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--research", action="store_true",
                        help="rewrite the research notes' tables instead of docs/results.md's")
    args = parser.parse_args(argv)
    tables = table_rows(document_tasks(DOC))
    for doc in (READINGS, PROBE_NOTE) if args.research else (DOC,):
        doc.write_text(rewrite(doc.read_text(), tables))
        shown = doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc
        print(f"{shown}: tables rewritten")


if __name__ == "__main__":
    main()
