"""The research notes' tables say what the committed runs say.

Most of those tables were written by hand beside the text that reads them; this test recomputes
their numbers from each run's `final_eval.json` and `metrics.csv` (the columns' definitions are
the ones the notes give), so that a copied or stale number fails here:

- research/2026-11-26-sound-critics-evidence.md: the sound preset's evidence (results/safe_sound,
  every column) and Hopper's first evidence under the max read of the cost pair, before selection
  round 5 (research/results/safe_sound_hopper_max, every column);
- research/2026-11-24-lambda-cadence.md: the previous preset's evidence (research/results/safe,
  the final evaluation's columns);
- research/2026-11-28-table1-readings.md: the tables of Table 1 that the reference leaves out
  (each seed's last policy, the paired tests over seeds, the probabilities task by task, the
  status line; docs/update_table1.py --research rewrites them);
- research/2026-11-28-contrastive-phase-probe.md: the probe's two tables
  (research/results/phase_probe).
"""

from __future__ import annotations

import csv
import json
import math
import re
import statistics

import pytest
from scipy.stats import ttest_rel

from tests.docs._tables import (
    ALGOS,
    RESEARCH_RESULTS,
    RESULTS,
    ROOT,
    SEEDS,
    close,
    complete_tasks,
    load_update_table1,
    numbers,
    pair_wins,
    table1_runs,
    table_rows,
)

RESEARCH = ROOT / "research"
EVIDENCE_NOTE = RESEARCH / "2026-11-26-sound-critics-evidence.md"
CADENCE_NOTE = RESEARCH / "2026-11-24-lambda-cadence.md"
READINGS_NOTE = RESEARCH / "2026-11-28-table1-readings.md"
PROBE_NOTE = RESEARCH / "2026-11-28-contrastive-phase-probe.md"
HEADER = (
    "| algo | policy | reward (mean ± std over seeds) | cost | reward per seed (10 / 20 / 30) |"
)
# The trees each evidence table reads.
TREES = {
    "safe_sound": RESULTS / "safe_sound",
    "safe_sound_hopper_max": RESEARCH_RESULTS / "safe_sound_hopper_max",
    "safe": RESEARCH_RESULTS / "safe",
}


def evidence_tables(text: str, title: str | None = None) -> dict[str, list[list[str]]]:
    """task -> the cells of each row of its table, from the note's section `title` (up to the
    next heading), or from the note's start."""
    section = text.split(title, 1)[1] if title else text.split("\n", 1)[1]
    section = re.split(r"\n##+ ", section, maxsplit=1)[0]
    tables: dict[str, list[list[str]]] = {}
    for block in re.split(r"\n(?=\*\*Safety)", section)[1:]:
        task = re.match(r"\*\*(Safety\w+-v\d)", block).group(1)
        if HEADER in block:
            tables[task] = table_rows(block, HEADER)
    return tables


def run_stats(root: str, task: str, algo: str, seed: int) -> dict:
    """The table's columns for one run of the tree `root`, computed from its files."""
    run = TREES[root] / f"{algo}_{task}" / f"seed{seed}"
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


EVIDENCE_TEXT = EVIDENCE_NOTE.read_text()
HOPPER_MAX_READ_SECTION = "### SafetyHopperVelocity-v1 under the max read"
SOUND = evidence_tables(EVIDENCE_TEXT)
HOPPER_MAX_READ = evidence_tables(EVIDENCE_TEXT, HOPPER_MAX_READ_SECTION)
FSRL_CRITICS = evidence_tables(
    CADENCE_NOTE.read_text(),
    "## The evidence: seeds 10, 20, 30, 1M frames, under `experiment=safe`",
)


def test_the_evidence_notes_have_their_tables():
    assert set(SOUND) == {
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


# ------------------------------------------------------------------------- the Table 1 readings
READINGS_TEXT = READINGS_NOTE.read_text()
TABLE1 = table_rows(READINGS_TEXT, "| task | algo | seeds | paper: reward / cost |")
PAIRED = table_rows(READINGS_TEXT, "| task | policy | reward (p) | cost (p) |")
PER_SEED = table_rows(READINGS_TEXT, "| task | algo | seed 10: reward / cost |")
POLICIES = (("last", lambda r: r), ("best-feasible", lambda r: r["best_feasible"]))
READINGS = (("cost lower", "cost_mean", -1.0), ("reward higher", "reward_mean", 1.0))


def test_the_readings_repeat_the_references_table1():
    reference = table_rows(
        (ROOT / "docs" / "results.md").read_text(), "| task | algo | seeds | paper: reward / cost |"
    )
    assert TABLE1 == reference


def test_table1_paired_tests_cover_the_complete_tasks():
    complete = complete_tasks(TABLE1)
    assert len(complete) == 16
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


def test_table1_per_seed_rows_cover_every_task():
    assert [(row[0], row[1]) for row in PER_SEED] == [(row[0], row[1]) for row in TABLE1]


@pytest.mark.parametrize("row", PER_SEED, ids=lambda row: f"{row[0]}-{row[1]}")
def test_table1_per_seed_row_is_each_runs_last_policy(row):
    task, algo, *cells = row
    runs = table1_runs(task, ALGOS[algo])
    for seed, cell in zip(SEEDS, cells, strict=True):
        reward, cost = numbers(cell)
        assert close(reward, runs[seed]["reward_mean"]), f"{task} {seed} {cell}"
        assert close(cost, runs[seed]["cost_mean"]), f"{task} {seed} {cell}"


def test_table1_per_task_probabilities_count_the_pairs_of_runs():
    # Counted here over the 9 pairs (S3RL seed, SAC-Lag seed) of each complete task: S3RL's
    # run costs less, earns more, a tie one half. The last row is their mean over the tasks,
    # the aggregate's point estimate.
    complete = complete_tasks(TABLE1)
    rows = table_rows(READINGS_TEXT, "| task | last: P(cost lower) |")
    assert sorted(row[0] for row in rows[:-1]) == sorted(complete)
    assert rows[-1][0] == "mean over the tasks"
    expected = {
        task: [pair_wins(task, policy, key, sign) for _, policy in POLICIES
               for _, key, sign in READINGS]
        for task in complete
    }
    for task, *cells in rows[:-1]:
        assert all(close(c, v) for c, v in zip(cells, expected[task], strict=True)), task
    means = [statistics.mean(column) for column in zip(*expected.values())]
    assert all(close(c, v) for c, v in zip(rows[-1][1:], means, strict=True))


def test_table1_status_line_counts_the_exported_runs():
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
        f"**Where it stands: {len(complete_tasks(TABLE1))} of {len(tasks)} tasks are complete; "
        f"{len(table1)} of the {planned} `sweep=table1` runs are exported.**"
    )
    assert line in READINGS_TEXT.splitlines()


# ------------------------------------------------------------------------------ the phase probe
PROBE = RESEARCH_RESULTS / "phase_probe"
PROBE_TEXT = PROBE_NOTE.read_text()


def test_phase_offset_table_is_the_continued_runs_metrics():
    # CarCircle-v0 S3RL seed 10 continued past 1M with T = 1500 (phases after gradient steps
    # that are multiples of 1500): each epoch's row, with the steps since the last phase.
    run = PROBE / "interval1500" / "s3rl_SafetyCarCircle-v0" / "seed10"
    config = json.loads((run / "config.json").read_text())
    assert config["algo"]["contrastive_cfg"]["update_interval"] == 1500
    with (run / "metrics.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if int(r["frames"]) > 1_000_000]
    written = table_rows(PROBE_TEXT, "| frames | gradient steps since the last phase |")
    assert len(written) == len(rows) == 9
    for cells, row in zip(written, rows, strict=True):
        assert cells[:2] == [row["frames"], str(int(row["grad_steps"]) % 1500)]
        for cell, (reward, cost) in zip(
            cells[2:], (("eval/reward", "eval/cost"), ("train/reward", "train/cost")), strict=True
        ):
            r, c = numbers(cell)
            assert close(r, float(row[reward])) and close(c, float(row[cost]))


def test_phase_probe_table_is_the_runs_at_1m_and_1000_steps_later():
    written = table_rows(PROBE_TEXT, "| task | algo | seed | at 1M: reward / cost |")
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


@pytest.mark.slow
def test_update_table1_rewrites_the_research_notes_unchanged(tmp_path, monkeypatch):
    # `docs/update_table1.py --research` (make research-report) gives back the committed notes,
    # and rewrites a stale status line, row and probe row.
    update_table1 = load_update_table1()
    stale_paths = {}
    for name, note, old_prefix, new in (
        ("READINGS", READINGS_NOTE, "**Where it stands:", "**Where it stands: 0 of 16.**"),
        ("PROBE_NOTE", PROBE_NOTE, "| 1010000 |", "| 1010000 | 7 | 1.0 / 1.0 | 1.0 / 1.0 |"),
    ):
        committed = note.read_text()
        line = next(line for line in committed.splitlines() if line.startswith(old_prefix))
        stale = tmp_path / note.name
        stale.write_text(committed.replace(line, new))
        monkeypatch.setattr(update_table1, name, stale)
        stale_paths[stale] = committed
    update_table1.main(["--research"])
    for stale, committed in stale_paths.items():
        assert stale.read_text() == committed
