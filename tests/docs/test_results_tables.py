"""The per-task evidence tables of docs/results.md say what the committed runs say.

Most of those tables are written by hand, beside the text that reads them (Table 1 in full's
are rewritten by docs/update_table1.py, also checked here); this test recomputes their
numbers from each run's `final_eval.json` and `metrics.csv` (the columns' definitions are the
ones docs/results.md gives), so that a copied or stale number fails here. Four sections hold
them: the sound preset's evidence (results/safe_sound, every column), Hopper's first evidence
under the max read of the cost pair, before selection round 5 (results/safe_sound_hopper_max,
every column), the previous preset's (results/safe, the final evaluation's columns), and Table 1
in full (results/safe_sound with results/table1 beside the paper's file: the sixteen tasks'
rows, the paired tests over seeds, rliable's aggregate over the complete tasks and the counts of
its cost profiles).
"""

from __future__ import annotations

import csv
import json
import math
import re
import statistics
from pathlib import Path

import pytest
from scipy.stats import ttest_rel

from s3rl_torchrl.report.paper import load_paper_results, paper_results_for

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "results.md"
RESULTS = ROOT / "results"
ALGOS = {"S3RL": "s3rl", "SAC-Lag": "sac_lag"}
SEEDS = (10, 20, 30)
HEADER = (
    "| algo | policy | reward (mean ± std over seeds) | cost | reward per seed (10 / 20 / 30) |"
)


SOUND_SECTION = "### The evidence (seeds 10, 20, 30, 1M frames)"
FSRL_CRITICS_SECTION = "### The evidence: seeds 10, 20, 30, 1M frames, under `experiment=safe`"
HOPPER_MAX_READ_SECTION = "#### SafetyHopperVelocity-v1 under the max read"


def evidence_tables(title: str) -> dict[str, list[list[str]]]:
    """task -> the cells of each row of its table, from the doc's section `title`."""
    text = DOC.read_text()
    section = text.split(title, 1)[1]
    section = re.split(r"\n##+ ", section, maxsplit=1)[0]
    tables: dict[str, list[list[str]]] = {}
    for block in re.split(r"\n(?=\*\*Safety)", section)[1:]:
        task = re.match(r"\*\*(Safety\w+-v\d)", block).group(1)
        if HEADER in block:
            tables[task] = table_rows(block, HEADER)
    return tables


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


def run_stats(root: str, task: str, algo: str, seed: int) -> dict:
    """The table's columns for one run of results/<root>, computed from its files."""
    run = RESULTS / root / f"{algo}_{task}" / f"seed{seed}"
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


SOUND = evidence_tables(SOUND_SECTION)
FSRL_CRITICS = evidence_tables(FSRL_CRITICS_SECTION)
HOPPER_MAX_READ = evidence_tables(HOPPER_MAX_READ_SECTION)


def test_the_evidence_sections_have_their_tables():
    # The complete tasks at the time of writing; more may be added, none may vanish.
    assert set(SOUND) >= {
        "SafetyBallRun-v0",
        "SafetyCarRun-v0",
        "SafetyDroneRun-v0",
        "SafetyBallCircle-v0",
        "SafetyHalfCheetahVelocity-v1",
        "SafetyHopperVelocity-v1",
        "SafetyPointGoal1-v0",
    }
    assert set(FSRL_CRITICS) == {
        "SafetyHalfCheetahVelocity-v1",
        "SafetyHopperVelocity-v1",
        "SafetyBallRun-v0",
    }
    assert set(HOPPER_MAX_READ) == {"SafetyHopperVelocity-v1"}


def check_final_evaluation(root: str, task: str, rows: list[list[str]]) -> list[list[dict]]:
    """The columns every evidence table shares: the final evaluation's reward and cost, over
    seeds and per seed, of the last policy and of the best-feasible checkpoint."""
    assert [(r[0], r[1]) for r in rows] == [
        ("S3RL", "last"),
        ("S3RL", "best-feasible"),
        ("SAC-Lag", "last"),
        ("SAC-Lag", "best-feasible"),
    ]
    per_algo = []
    for last, best in (rows[0:2], rows[2:4]):
        runs = [run_stats(root, task, ALGOS[last[0]], seed) for seed in SEEDS]
        where = f"{root} {task} {last[0]}"
        for row, reward_key, cost_key in (
            (last, "reward", "cost"),
            (best, "best_reward", "best_cost"),
        ):
            for cell, key in ((row[2], reward_key), (row[3], cost_key)):
                values = [run[key] for run in runs]
                mean, std = numbers(cell)
                assert close(mean, statistics.mean(values)), f"{where} {row[1]} mean: {cell}"
                assert close(std, statistics.stdev(values)), f"{where} {row[1]} std: {cell}"
            for cell, key in ((row[4], reward_key), (row[5], cost_key)):
                written = numbers(cell)
                if not written and row is best:  # most tables leave these cells empty
                    continue
                assert len(written) == 3, f"{where} {row[1]}: {cell}"
                for w, run in zip(written, runs):
                    assert close(w, run[key]), f"{where} {row[1]} per seed: {cell}"
        per_algo.append(runs)
    return per_algo


@pytest.mark.parametrize(
    "root, task",
    [("safe_sound", task) for task in sorted(SOUND)]
    + [("safe_sound_hopper_max", task) for task in sorted(HOPPER_MAX_READ)],
)
def test_sound_preset_table_matches_the_committed_runs(root, task):
    rows = (SOUND if root == "safe_sound" else HOPPER_MAX_READ)[task]
    per_algo = check_final_evaluation(root, task, rows)
    for last, runs in zip((rows[0], rows[2]), per_algo):
        where = f"{task} {last[0]}"
        lambdas = numbers(last[6])
        assert len(lambdas) == 9, f"{where}: {last[6]}"
        for i, run in enumerate(runs):
            assert close(lambdas[2 * i], run["lambda_peak"]), f"{where} lambda peak: {last[6]}"
            assert int(lambdas[2 * i + 1]) == run["lambda_peak_k"], f"{where} peak at: {last[6]}"
            assert close(lambdas[6 + i], run["lambda_end"]), f"{where} lambda end: {last[6]}"
        for w, run in zip(numbers(last[7]), runs, strict=True):
            assert close(w, run["over"]), f"{where} second half over the limit: {last[7]}"
        last20 = numbers(last[8])
        assert len(last20) == 9, f"{where}: {last[8]}"
        for i, run in enumerate(runs):
            for j in range(3):
                assert close(last20[3 * i + j], run["last20"][j]), f"{where} last 20%: {last[8]}"


@pytest.mark.parametrize("task", sorted(FSRL_CRITICS))
def test_fsrl_critics_table_matches_the_committed_runs(task):
    check_final_evaluation("safe", task, FSRL_CRITICS[task])


# Table 1 in full: the sixteen tasks' final evaluation, from results/safe_sound (the evidence's
# seven tasks) and results/table1 (sweep=table1's nine), beside the paper's file.
TABLE1_SECTION = "## Table 1 in full: sixteen tasks under `experiment=safe`"
TABLE1_ROOTS = ("safe_sound", "table1")
TABLE1_HEADER = "| task | algo | seeds | paper: reward / cost |"
PAIRED_HEADER = "| task | policy | reward (p) | cost (p) |"


def section_table(title: str, header: str) -> list[list[str]]:
    """The cells of each row of the table under `header` in the doc's section `title`."""
    section = re.split(r"\n## ", DOC.read_text().split(title, 1)[1], maxsplit=1)[0]
    return table_rows(section, header)


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


def paper_table1(task: str, algo: str) -> dict[str, float]:
    """The paper's Table 1 reward and cost of (task, algo), by any of the task's ids, from
    the package's copy of it (tests/report checks that file against the paper's tables)."""
    return {
        v.metric: v.mean
        for v in paper_results_for(task)
        if v.table == "Table 1" and v.algo == algo and v.metric in ("reward", "cost")
    }


def complete_tasks() -> list[str]:
    """The tasks of Table 1 in full whose both algos have every seed exported, in its order."""
    return [
        row[0]
        for row in TABLE1
        if row[1] == "S3RL"
        and all(len(table1_runs(row[0], algo)) == len(SEEDS) for algo in ("s3rl", "sac_lag"))
    ]


TABLE1 = section_table(TABLE1_SECTION, TABLE1_HEADER)
PAIRED = section_table(TABLE1_SECTION, PAIRED_HEADER)


def test_table1_has_every_task_of_the_paper_for_both_algos():
    paper = {(v.task, v.algo) for v in load_paper_results() if v.table == "Table 1" and v.algo}
    written = {
        (v.task, v.algo)
        for task, algo, *_ in TABLE1
        for v in paper_results_for(task)
        if v.table == "Table 1" and v.algo == ALGOS[algo]
    }
    assert written == paper and len(TABLE1) == len(paper) == 32


@pytest.mark.parametrize("row", TABLE1, ids=lambda row: f"{row[0]}-{row[1]}")
def test_table1_row_matches_the_paper_and_the_committed_runs(row):
    task, algo, seeds, paper, last, best = row
    expected = paper_table1(task, ALGOS[algo])
    paper_reward, paper_cost = numbers(paper)
    assert close(paper_reward, expected["reward"]) and close(paper_cost, expected["cost"])
    runs = table1_runs(task, ALGOS[algo])
    assert int(seeds) == len(runs), f"{task} {algo}: {len(runs)} runs exported"
    if not runs:
        assert last == best == "pending"
        return
    for cell, final in ((last, lambda r: r), (best, lambda r: r["best_feasible"])):
        reward, cost = numbers(cell)
        assert close(reward, statistics.mean(final(r)["reward_mean"] for r in runs.values()))
        assert close(cost, statistics.mean(final(r)["cost_mean"] for r in runs.values()))


def test_table1_paired_tests_cover_the_complete_tasks():
    complete = complete_tasks()
    assert [row[0] for row in PAIRED] == [task for task in complete for _ in range(2)]
    assert [row[1] for row in PAIRED] == ["last", "best-feasible"] * len(complete)


@pytest.mark.parametrize("row", PAIRED, ids=lambda row: f"{row[0]}-{row[1]}")
def test_table1_paired_test_matches_scipy(row):
    task, policy, *cells = row
    s3rl, sac_lag = table1_runs(task, "s3rl"), table1_runs(task, "sac_lag")
    final = (lambda r: r) if policy == "last" else (lambda r: r["best_feasible"])
    for cell, key in zip(cells, ("reward_mean", "cost_mean"), strict=True):
        a = [final(s3rl[seed])[key] for seed in SEEDS]
        b = [final(sac_lag[seed])[key] for seed in SEEDS]
        expected = ttest_rel(a, b).pvalue
        if math.isnan(expected):  # the same difference on every seed: no test
            (difference,) = numbers(cell)
            assert cell.endswith("(p undefined)"), f"{task} {cell}"
        else:
            difference, p = numbers(cell)
            assert close(p, expected), f"{task} {cell}"
        assert close(difference, statistics.mean(a) - statistics.mean(b)), f"{task} {cell}"


ANSWER_HEADER = "| policy | P(S3RL's cost lower) | P(S3RL's reward higher) |"
PER_SEED_HEADER = "| task | algo | seed 10: reward / cost |"
PER_SEED = section_table(TABLE1_SECTION, PER_SEED_HEADER)


def test_table1_per_seed_rows_cover_the_tasks_with_a_finished_run():
    started = [
        (task, algo)
        for task, algo, *_ in TABLE1
        if table1_runs(task, "s3rl") or table1_runs(task, "sac_lag")
    ]
    assert [(row[0], row[1]) for row in PER_SEED] == started


@pytest.mark.parametrize("row", PER_SEED, ids=lambda row: f"{row[0]}-{row[1]}")
def test_table1_per_seed_row_is_each_runs_last_policy(row):
    task, algo, *cells = row
    runs = table1_runs(task, ALGOS[algo])
    for seed, cell in zip(SEEDS, cells, strict=True):
        if seed not in runs:
            assert cell == "pending"
            continue
        reward, cost = numbers(cell)
        assert close(reward, runs[seed]["reward_mean"]), f"{task} {seed} {cell}"
        assert close(cost, runs[seed]["cost_mean"]), f"{task} {seed} {cell}"


def test_table1_answer_across_tasks_is_the_aggregate_of_the_complete_tasks():
    # The aggregate quoted before the sixteen tasks are in: rliable's statistics over the tasks
    # whose both algos have three seeds (the report's own defaults: 2000 resamples, seed 0).
    from s3rl_torchrl.report.aggregate import aggregate
    from s3rl_torchrl.report.runs import find_runs, group_runs

    groups = group_runs([run for root in TABLE1_ROOTS for run in find_runs(RESULTS / root)])
    complete = set(complete_tasks())
    result = aggregate([g for g in groups if g.task in complete], "s3rl")
    written = {row[0]: row[1:] for row in section_table(TABLE1_SECTION, ANSWER_HEADER)}
    assert set(written) == {"last", "best-feasible"}
    for read in result.protocols:
        cost, reward, within, iqm = written[read.protocol.replace("_", "-")]
        (pair,) = read.pairs
        assert len(pair.tasks) == len(complete)
        assert (cost, reward) == (pair.cost.cell(), pair.reward.cell())
        s3rl, sac_lag = read.algos
        assert within == " / ".join("{} of {}".format(*row.within_count) for row in (s3rl, sac_lag))
        assert iqm == f"{s3rl.cost_ratio.cell()} / {sac_lag.cost_ratio.cell()}"


PER_TASK_HEADER = "| task | last: P(cost lower) |"
POLICIES = (("last", lambda r: r), ("best-feasible", lambda r: r["best_feasible"]))
# (reading, final_eval.json key, sign that makes higher better)
READINGS = (("cost lower", "cost_mean", -1.0), ("reward higher", "reward_mean", 1.0))


def pair_wins(task: str, policy, key: str, sign: float) -> float:
    """The share of a task's 9 pairs of runs (S3RL seed, SAC-Lag seed) in which S3RL's is
    better, a tie one half, counted from the runs' final_eval.json."""
    ours = [sign * policy(r)[key] for r in table1_runs(task, "s3rl").values()]
    theirs = [sign * policy(r)[key] for r in table1_runs(task, "sac_lag").values()]
    pairs = [(a > b) + 0.5 * (a == b) for a in ours for b in theirs]
    return sum(pairs) / len(pairs)


def test_table1_per_task_probabilities_count_the_pairs_of_runs():
    # Counted here over the 9 pairs (S3RL seed, SAC-Lag seed) of each complete task: S3RL's
    # run costs less, earns more, a tie one half. The last row is their mean over the tasks,
    # which is the answer table's point estimate.
    complete = complete_tasks()
    rows = section_table(TABLE1_SECTION, PER_TASK_HEADER)
    assert sorted(row[0] for row in rows[:-1]) == sorted(complete)
    assert rows[-1][0] == "mean over the tasks"
    policies = POLICIES
    expected = {
        task: [pair_wins(task, policy, key, sign) for _, policy in policies
               for _, key, sign in READINGS]
        for task in complete
    }
    for task, *cells in rows[:-1]:
        assert all(close(c, v) for c, v in zip(cells, expected[task], strict=True)), task
    means = [statistics.mean(column) for column in zip(*expected.values())]
    assert all(close(c, v) for c, v in zip(rows[-1][1:], means, strict=True))
    answer = {row[0]: row[1:3] for row in section_table(TABLE1_SECTION, ANSWER_HEADER)}
    assert [numbers(cell)[0] for name, _ in policies for cell in answer[name]] == rows[-1][1:]


WITHOUT_ONE_TASK_HEADER = "| reading | every complete task |"


def test_table1_without_one_task_leaves_out_the_tasks_that_move_it_most():
    # Each reading without one complete task is the mean of the other tasks' pair counts; the
    # rows name the task whose removal lowers it most and the one whose removal raises it most
    # (the first in task order on a tie), and quote the aggregate's bootstrap over the rest.
    import numpy as np

    from s3rl_torchrl.report.aggregate import probability_of_improvement

    complete = sorted(complete_tasks())
    written = {row[0]: row[1:] for row in section_table(TABLE1_SECTION, WITHOUT_ONE_TASK_HEADER)}
    answer = {row[0]: row[1:3] for row in section_table(TABLE1_SECTION, ANSWER_HEADER)}
    assert len(written) == len(POLICIES) * len(READINGS)
    for (policy_name, policy), (j, (name, key, sign)) in (
        (policy, reading) for policy in POLICIES for reading in enumerate(READINGS)
    ):
        every, lowest, highest = written[f"{policy_name}: P(S3RL's {name})"]
        assert every == answer[policy_name][j]
        wins = {task: pair_wins(task, policy, key, sign) for task in complete}
        without = {t: statistics.mean(w for u, w in wins.items() if u != t) for t in complete}
        for cell, target in ((lowest, min(without.values())), (highest, max(without.values()))):
            estimate, left_out = cell.split(" without ")
            assert left_out == next(t for t in complete if without[t] == target)
            runs = [
                {t: np.array([policy(r)[key] for r in table1_runs(t, algo).values()])
                 for t in complete if t != left_out}
                for algo in ("s3rl", "sac_lag")
            ]
            bootstrapped, _ = probability_of_improvement(*runs, lower_is_better=sign < 0)
            assert close(numbers(estimate)[0], target)
            assert estimate == bootstrapped.cell(), (policy_name, name, left_out)


PROFILE_HEADER = "| policy | algo | cost / limit: 0 |"
PROFILE = section_table(TABLE1_SECTION, PROFILE_HEADER)


def table1_cost_limit(task: str, algo: str) -> float:
    """The cost limit the exported runs of (task, algo) trained and were judged at."""
    (limit,) = {
        json.loads(path.read_text())["task"]["cost_limit"]
        for root in TABLE1_ROOTS
        for path in (RESULTS / root / f"{algo}_{task}").glob("seed*/config.json")
    }
    return limit


def test_table1_cost_profile_counts_are_the_complete_tasks_runs():
    # Counted here from each run's final evaluation and its config's limit: how many of an
    # algo's runs over the complete tasks have cost / limit at or below 0, 0.2, 0.5, 1 and 2.
    complete = complete_tasks()
    # Each run's final evaluation beside its limit, read once for both protocols.
    runs = {algo: [] for algo in ALGOS.values()}
    for task in complete:
        for algo in ALGOS.values():
            limit = table1_cost_limit(task, algo)
            runs[algo] += [(evaluation, limit) for evaluation in table1_runs(task, algo).values()]
    expected = []
    for policy, final in (("last", lambda r: r), ("best-feasible", lambda r: r["best_feasible"])):
        for name, algo in ALGOS.items():
            ratios = [final(run)["cost_mean"] / limit for run, limit in runs[algo]]
            assert len(ratios) == len(SEEDS) * len(complete)
            counts = [sum(r <= t for r in ratios) for t in (0.0, 0.2, 0.5, 1.0, 2.0)]
            expected.append([policy, name, *(f"{n} of {len(ratios)}" for n in counts)])
    assert PROFILE == expected


def test_table1_status_line_counts_the_exported_runs():
    # Counted from the files: the tasks the evidence tree has no run of are the ones
    # sweep=table1 runs, both algos, three seeds each.
    section = DOC.read_text().split(TABLE1_SECTION, 1)[1]
    tasks = [row[0] for row in TABLE1 if row[1] == "S3RL"]
    evidence = {
        group.name.removeprefix("sac_lag_").removeprefix("s3rl_")
        for group in (RESULTS / "safe_sound").iterdir()
        if any(group.glob("seed*/final_eval.json"))
    }
    table1 = list((RESULTS / "table1").glob("*/seed*/final_eval.json"))
    planned = 2 * len(SEEDS) * len(set(tasks) - evidence)
    assert planned == 54
    line = (
        f"**Where it stands: {len(complete_tasks())} of {len(tasks)} tasks are complete; "
        f"{len(table1)} of the {planned} `sweep=table1` runs are exported.**"
    )
    assert line in section.splitlines()


@pytest.fixture(scope="module")
def update_table1():
    """docs/update_table1.py (make report runs it; not a package module) as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "update_table1", ROOT / "docs" / "update_table1.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_update_table1_rewrites_the_committed_tables_unchanged(
    update_table1, tmp_path, monkeypatch
):
    # The script writes the tables and the status line the tests above check; on the committed
    # runs it must give back the committed doc, and a stale row and status must be rewritten.
    committed = DOC.read_text()
    row = next(
        line for line in committed.splitlines() if line.startswith("| SafetyCarRun-v0 | S3RL")
    )
    status = next(line for line in committed.splitlines() if line.startswith("**Where it stands:"))
    # The phase probe's tables too: an epoch row and a probed run's row.
    epoch = next(line for line in committed.splitlines() if line.startswith("| 1010000 |"))
    probed = next(
        line for line in committed.splitlines() if line.startswith("| SafetyAntRun-v0 | S3RL | 10 |")
    )
    stale = tmp_path / "results.md"
    stale.write_text(
        committed.replace(row, row.replace("554.00", "1.00"))
        .replace(status, "**Where it stands: 0 of 16 tasks are complete.**")
        .replace(epoch, "| 1010000 | 7 | 1.0 / 1.0 | 1.0 / 1.0 |")
        .replace(probed, "| SafetyAntRun-v0 | S3RL | 10 | 1.0 / 1.0 | 1.0 / 1.0 |")
    )
    monkeypatch.setattr(update_table1, "DOC", stale)
    update_table1.main()
    assert stale.read_text() == committed


def test_update_table1_paired_cell_by_hand(update_table1):
    # S3RL minus SAC-Lag over seeds 10, 20, 30. Reward differences 1, 2, 3: mean 2, std 1, so
    # t = 2 / (1 / sqrt(3)) = 3.464 on 2 degrees of freedom, two-sided p = 0.0742. Costs all
    # zero: no spread, no test.
    def final(reward):
        return {"reward_mean": reward, "cost_mean": 0.0, "best_feasible": {}}

    s3rl = {10: final(11.0), 20: final(22.0), 30: final(33.0)}
    sac_lag = {10: final(10.0), 20: final(20.0), 30: final(30.0)}
    assert update_table1.paired(s3rl, sac_lag, "last") == "+2.00 (p = 0.07) | +0.00 (p undefined)"


PHASE_SECTION = "### When S3RL is evaluated right after a contrastive phase"
PROBE = RESULTS / "phase_probe"


def test_phase_offset_table_is_the_continued_runs_metrics():
    # CarCircle-v0 S3RL seed 10 continued past 1M with T = 1500 (phases after gradient steps
    # that are multiples of 1500): each epoch's row, with the steps since the last phase.
    run = PROBE / "interval1500" / "s3rl_SafetyCarCircle-v0" / "seed10"
    config = json.loads((run / "config.json").read_text())
    assert config["algo"]["contrastive_cfg"]["update_interval"] == 1500
    with (run / "metrics.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if int(r["frames"]) > 1_000_000]
    written = section_table(PHASE_SECTION, "| frames | gradient steps since the last phase |")
    assert len(written) == len(rows) == 9
    for cells, row in zip(written, rows, strict=True):
        assert cells[:2] == [row["frames"], str(int(row["grad_steps"]) % 1500)]
        for cell, (reward, cost) in zip(
            cells[2:], (("eval/reward", "eval/cost"), ("train/reward", "train/cost")), strict=True
        ):
            r, c = numbers(cell)
            assert close(r, float(row[reward])) and close(c, float(row[cost]))


def test_phase_probe_table_is_the_runs_at_1m_and_1000_steps_later():
    written = section_table(PHASE_SECTION, "| task | algo | seed | at 1M: reward / cost |")
    probed = sorted(PROBE.glob("after1000/*/seed*/final_eval.json"))
    assert len(written) == len(probed) == 30
    for task, name, seed, at_1m, later in written:
        group = f"{ALGOS[name]}_{task}/seed{seed}"
        config = json.loads((PROBE / "after1000" / group / "config.json").read_text())
        # 5000 more frames (1000 gradient steps at 0.2 per frame) with no phase in them.
        assert config["collector"]["total_frames"] == 1_005_000
        assert config["algo"]["contrastive_cfg"]["update_interval"] > 1000
        for cell, path in (
            (at_1m, RESULTS / "table1" / group / "final_eval.json"),
            (later, PROBE / "after1000" / group / "final_eval.json"),
        ):
            final = json.loads(path.read_text())
            r, c = numbers(cell)
            assert close(r, final["reward_mean"]) and close(c, final["cost_mean"]), (group, cell)
