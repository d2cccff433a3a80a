"""s3rl-report's aggregate over tasks (report.aggregate, rliable): a case small enough to work
out by hand (2 tasks x 3 seeds x 2 algos), intervals in the cases where the bootstrap cannot
vary, and the section that s3rl-report writes."""

from __future__ import annotations

import sys
from fractions import Fraction as F

import numpy as np
import pytest

from s3rl_torchrl.report import aggregate as agg
from s3rl_torchrl.report.cli import main
from s3rl_torchrl.report.runs import find_runs, group_runs

REPS = 200  # enough for the checks here, fast
TASK_A, TASK_B = "TaskA-v0", "TaskB-v0"
LIMITS = {TASK_A: 10.0, TASK_B: 20.0}
# (task, algo) -> (rewards, costs) of seeds 1, 2, 3: each run's final-evaluation mean.
FINAL = {
    (TASK_A, "s3rl"): ([100.0, 120.0, 140.0], [0.0, 5.0, 12.0]),
    (TASK_A, "sac_lag"): ([110.0, 90.0, 150.0], [8.0, 15.0, 20.0]),
    (TASK_B, "s3rl"): ([10.0, 30.0, 50.0], [10.0, 20.0, 30.0]),
    (TASK_B, "sac_lag"): ([20.0, 40.0, 0.0], [40.0, 0.0, 10.0]),
}
# Every run's logged evaluations (metrics.csv eval/reward): the lowest is each task's floor.
LOGGED = {TASK_A: [50.0, 60.0, 70.0], TASK_B: [-20.0, 0.0, 5.0]}


def _write(root, make_run, best_feasible=None):
    for (task, algo), (rewards, costs) in FINAL.items():
        for seed, reward, cost in zip((1, 2, 3), rewards, costs):
            curve = {"frames": [200, 400, 600], "eval/reward": LOGGED[task],
                     "eval/cost": [0.0, 0.0, 0.0]}
            episodes = {"rewards": [reward, reward], "costs": [cost, cost],
                        "lengths": [50, 50], "safe_steps": [50, 50]}
            best = (best_feasible or {}).get((task, algo, seed))
            make_run(root / f"{algo}_{task}" / f"seed{seed}", task, algo, seed, episodes,
                     curve=curve, best_feasible=best, task__cost_limit=LIMITS[task])
    return group_runs(find_runs(root))


def test_hand_computed_case(tmp_path, make_run):
    groups = _write(tmp_path / "runs", make_run)

    # Anchors. TaskA: floor 50 (logged), top 120 (s3rl seed 2, cost 5 <= 10; 140 and 150 cost
    # more than 10). TaskB: floor -20 (logged), top 40 (sac_lag seed 2, cost 0 <= 20).
    anchors = agg.reward_anchors(groups)
    assert (anchors[TASK_A].floor, anchors[TASK_A].top) == (50.0, 120.0)
    assert (anchors[TASK_B].floor, anchors[TASK_B].top) == (-20.0, 40.0)
    assert anchors[TASK_A].top_from == "s3rl seed 2, last policy"
    assert anchors[TASK_B].floor_from == "s3rl seed 1, 0.2k frames"

    result = agg.aggregate(groups, "s3rl", reps=REPS)
    assert [p.protocol for p in result.protocols] == ["last"]  # no best_feasible entries
    rows = {row.label: row for row in result.protocols[0].algos}
    assert list(rows) == ["s3rl", "sac_lag"]

    # cost / limit. s3rl: 0, .5, 1.2 (A) and .5, 1, 1.5 (B); sorted 0 .5 .5 1 1.2 1.5; the IQM
    # of 6 runs drops one at each end: (.5 + .5 + 1 + 1.2) / 4 = 0.8.
    # sac_lag: .8, 1.5, 2 (A) and 2, 0, .5 (B): (.5 + .8 + 1.5 + 2) / 4 = 1.2.
    assert rows["s3rl"].cost_ratio.point == pytest.approx(0.8)
    assert rows["sac_lag"].cost_ratio.point == pytest.approx(1.2)

    # Normalised reward. s3rl: (100-50)/70, 70/70, 90/70 (A); 30/60, 50/60, 70/60 (B) =
    # 5/7, 1, 9/7, 1/2, 5/6, 7/6 -> middle four 5/7 + 5/6 + 1 + 7/6 = 26/7, IQM 13/14.
    # sac_lag: 6/7, 4/7, 10/7 (A); 2/3, 1, 1/3 (B) -> 4/7 + 2/3 + 6/7 + 1 = 65/21, IQM 65/84.
    assert rows["s3rl"].normalised_reward.point == pytest.approx(float(F(13, 14)))
    assert rows["sac_lag"].normalised_reward.point == pytest.approx(float(F(65, 84)))

    # Within the limit (cost <= limit; 20 at a limit of 20 is within): s3rl 0, 5 | 10, 20 ->
    # 4 of 6; sac_lag 8 | 0, 10 -> 3 of 6.
    assert rows["s3rl"].within_count == (4, 6)
    assert rows["s3rl"].within.point == pytest.approx(4 / 6)
    assert rows["sac_lag"].within_count == (3, 6)

    # Probability of improvement, s3rl over sac_lag, over all 9 pairs of runs of a task.
    # Reward A: 100 beats 90; 120 and 140 beat 110 and 90 -> 5/9. B: 10 > 0; 30 > 20, 0;
    # 50 > all -> 6/9. Mean 11/18.
    # Cost (lower wins) A: 0 and 5 beat all three, 12 beats 15 and 20 -> 8/9. B: 10 < 40 and
    # ties 10 (one half); 20 < 40; 30 < 40 -> 3.5/9. Mean 23/36.
    (pair,) = result.protocols[0].pairs
    assert (pair.first, pair.second, pair.tasks) == ("s3rl", "sac_lag", [TASK_A, TASK_B])
    assert pair.reward.point == pytest.approx(float(F(11, 18)))
    assert pair.cost.point == pytest.approx(float(F(23, 36)))
    # The same per task, as the report's per-task table shows them.
    assert pair.reward_by_task == pytest.approx({TASK_A: 5 / 9, TASK_B: 6 / 9})
    assert pair.cost_by_task == pytest.approx({TASK_A: 8 / 9, TASK_B: 3.5 / 9})

    # Every interval holds its point estimate and stays within what the runs allow.
    for estimate in (*(getattr(r, k) for r in rows.values()
                       for k in ("cost_ratio", "normalised_reward", "within")),
                     pair.reward, pair.cost):
        assert estimate.low <= estimate.point + 1e-12 and estimate.point <= estimate.high + 1e-12
    assert 0.0 <= pair.cost.low and pair.cost.high <= 1.0
    assert 0.0 <= rows["s3rl"].cost_ratio.low and rows["s3rl"].cost_ratio.high <= 1.5

    # The same seed gives the same intervals; NumPy's global generator is left as it was.
    np.random.seed(7)
    before = np.random.get_state()[1].copy()
    again = agg.aggregate(groups, "s3rl", reps=REPS)
    assert np.array_equal(np.random.get_state()[1], before)
    assert again.protocols[0].pairs[0].cost == pair.cost
    assert again.protocols[0].algos[0].normalised_reward == rows["s3rl"].normalised_reward


def test_intervals_where_no_resample_can_differ():
    """Each task's runs all within the limit: every resample's share is 1. Every s3rl run of a
    task beats every other run of it: every resample's probability of improvement is 1. One
    value per task repeated: every resample's IQM is that value's mean."""
    within = {"a": np.ones(3), "b": np.ones(4)}
    assert agg.share(within, REPS) == agg.Estimate(1.0, 1.0, 1.0)
    x = {"a": np.array([5.0, 6.0, 7.0]), "b": np.array([1.0, 2.0])}
    y = {"a": np.array([1.0, 2.0, 3.0]), "b": np.array([-1.0, 0.0]), "c": np.array([9.0])}
    estimate, tasks = agg.probability_of_improvement(x, y, reps=REPS)
    assert tasks == ["a", "b"] and estimate == agg.Estimate(1.0, 1.0, 1.0)
    lower, _ = agg.probability_of_improvement(x, y, lower_is_better=True, reps=REPS)
    assert lower == agg.Estimate(0.0, 0.0, 0.0)
    same = agg.interquartile_mean({"a": np.full(3, 2.0), "b": np.full(3, 2.0)}, REPS)
    assert same == agg.Estimate(2.0, 2.0, 2.0)
    # The profile: runs 0, 1, 2, 3 -> fraction above -1, 0.5, 2.5 is 1, 3/4, 1/4; at or
    # below 0.5: 1/4.
    profile, low, high = agg.performance_profile({"a": np.array([0.0, 1.0, 2.0, 3.0])},
                                                 np.array([-1.0, 0.5, 2.5]), reps=REPS)
    np.testing.assert_allclose(profile, [1.0, 0.75, 0.25])
    assert np.all(low <= profile) and np.all(profile <= high)
    at_most, _, _ = agg.performance_profile({"a": np.array([0.0, 1.0, 2.0, 3.0])},
                                            np.array([0.5]), at_most=True, reps=REPS)
    np.testing.assert_allclose(at_most, [0.25])


def test_the_vectorised_statistics_are_rliables():
    """The bootstrap's resamples use numpy versions of rliable's per-task probability of
    improvement and run score distribution (speed): the same numbers, ties included."""
    from rliable import library, metrics

    rng = np.random.default_rng(0)
    for n, m in ((1, 1), (3, 3), (2, 5), (6, 4)):
        x = rng.integers(0, 4, size=(n, 1)).astype(float)  # few values: many ties
        y = rng.integers(0, 4, size=(m, 1)).astype(float)
        assert agg._improvement(x, y) == pytest.approx(metrics.probability_of_improvement(x, y))
    scores = {"a": rng.integers(0, 5, size=4).astype(float), "b": rng.normal(size=3)}
    taus = np.linspace(-1.0, 5.0, 13)
    profile, _, _ = agg.performance_profile(scores, taus, reps=10)
    pooled = np.concatenate([scores["a"], scores["b"]])
    np.testing.assert_allclose(profile, library.score_distributions(pooled, taus))


@pytest.mark.parametrize("sizes", [(3, 3, 3), (1, 4, 2, 5), (6,)])
def test_the_bootstrap_is_rliables_interval_estimate(sizes):
    """report.aggregate.bootstrap draws its resamples without np.random.choice (speed): the
    point and the interval stay library.get_interval_estimates', draw for draw, for equal and
    unequal strata and a statistic with several values."""
    from rliable import library

    rng = np.random.default_rng(3)
    strata = [rng.normal(size=(n, 1)) for n in sizes]

    def func(*cols):
        pooled = np.concatenate(cols)
        return np.array([pooled.mean(), np.median(pooled), (pooled > 0).mean()])

    point, low, high = agg.bootstrap(func, strata, reps=300, seed=11)
    np.random.seed(11)
    points, intervals = library.get_interval_estimates({"s": strata}, func, reps=300)
    np.testing.assert_array_equal(point, points["s"])
    np.testing.assert_array_equal(np.stack([low, high]), intervals["s"])
    assert np.any(low < high)  # resamples that differ: the draws were compared, not constants


def test_best_feasible_checkpoint_gets_its_own_aggregate_and_moves_the_top(tmp_path, make_run):
    # s3rl seed 1's best-feasible checkpoint on TaskA: reward 130 at cost 2 (within 10): the
    # new top; its last policy is unchanged.
    best = {(TASK_A, "s3rl", 1): {"rewards": [130.0, 130.0], "costs": [2.0, 2.0],
                                  "lengths": [50, 50], "safe_steps": [50, 50]}}
    groups = _write(tmp_path / "runs", make_run, best)
    anchors = agg.reward_anchors(groups)
    assert anchors[TASK_A].top == 130.0
    assert anchors[TASK_A].top_from.startswith("s3rl seed 1, best-feasible checkpoint")
    result = agg.aggregate(groups, "s3rl", reps=REPS)
    last, best_read = result.protocols
    assert best_read.protocol == "best_feasible"
    (row,) = best_read.algos  # only s3rl seed 1 of TaskA has the entry
    assert (row.label, row.tasks, row.runs) == ("s3rl", 1, 1)
    assert row.normalised_reward.point == pytest.approx(1.0)
    assert best_read.pairs == []  # sac_lag has no best-feasible evaluation


def test_s3rl_report_writes_the_aggregate_section(tmp_path, make_run, capsys):
    _write(tmp_path / "runs", make_run)
    args = [str(tmp_path / "runs"), "--no-embeddings", "--aggregate-reps", str(REPS)]
    assert main([*args, "--out", str(tmp_path / "r1")]) == 0
    text = (tmp_path / "r1" / "report.md").read_text()
    section = text.split("## Aggregate over tasks (rliable)", 1)[1].split("\n## ", 1)[0]
    assert "### Last policy" in section and "Best-feasible" not in section
    assert f"{TASK_A} | 10 | 50.00 (s3rl seed 1, 0.2k frames) | 120.00 (s3rl seed 2, last " \
           "policy) |" in section
    s3rl = next(line for line in section.splitlines() if line.startswith("| s3rl | 2 | 6 |"))
    assert "| 0.80 [" in s3rl and "| 0.93 [" in s3rl and "(4 of 6) |" in s3rl
    pair = next(line for line in section.splitlines() if line.startswith("| s3rl over sac_lag"))
    assert f"| {TASK_A}, {TASK_B} | 6 vs 6 | 0.64 [" in pair and "| 0.61 [" in pair
    # Per task: cost 8/9 and 3.5/9, reward 5/9 and 6/9 (the hand-computed case above).
    assert f"| s3rl over sac_lag | {TASK_A} | 0.89 | 0.56 |" in section
    assert f"| s3rl over sac_lag | {TASK_B} | 0.39 | 0.67 |" in section
    assert f"{REPS} resamples, NumPy seed 0" in section
    for ext in ("png", "svg"):
        assert (tmp_path / "r1" / f"{agg.AGGREGATE_FIGURE}.{ext}").stat().st_size > 0

    # Rebuilt: the same section and the same SVG, byte for byte.
    assert main([*args, "--out", str(tmp_path / "r2")]) == 0
    rebuilt = (tmp_path / "r2" / "report.md").read_text()
    assert rebuilt.split("## Aggregate", 1)[1].split("\n## Figure 2", 1)[0] == \
        text.split("## Aggregate", 1)[1].split("\n## Figure 2", 1)[0]
    svg = f"{agg.AGGREGATE_FIGURE}.svg"
    assert (tmp_path / "r2" / svg).read_bytes() == (tmp_path / "r1" / svg).read_bytes()

    assert main([*args, "--out", str(tmp_path / "r3"), "--no-aggregate"]) == 0
    assert "Aggregate" not in (tmp_path / "r3" / "report.md").read_text()


def test_without_rliable_the_report_says_what_to_install(tmp_path, make_run, monkeypatch,
                                                         capsys):
    _write(tmp_path / "runs", make_run)
    monkeypatch.setitem(sys.modules, "rliable", None)  # import rliable -> ImportError
    args = [str(tmp_path / "runs"), "--no-embeddings"]
    assert main([*args, "--out", str(tmp_path / "r")]) == 0
    text = (tmp_path / "r" / "report.md").read_text()
    assert 'Not computed: rliable is not installed' in text
    assert 'pip install "s3rl-torchrl[report]"' in text
    assert 'pip install "s3rl-torchrl[report]"' in capsys.readouterr().err  # the note
    assert main([*args, "--out", str(tmp_path / "r2"), "--aggregate"]) == 2
    assert 'pip install "s3rl-torchrl[report]"' in capsys.readouterr().err
