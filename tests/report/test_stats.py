"""Table 1's statistics against numpy and scipy.stats called directly on the same numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from s3rl_torchrl.report.runs import find_runs, group_runs
from s3rl_torchrl.report.stats import (
    compare_groups,
    learning_curve,
    paired_seed_test,
    summarize,
    welch_episode_test,
    within_seed_share,
)

REF = {1: 10.0, 2: 14.5, 3: 9.0, 4: 13.0}
BASE = {1: 8.0, 2: 11.0, 3: 9.5, 5: 100.0}  # seed 4 missing, seed 5 extra


def test_paired_test_uses_only_common_seeds_and_matches_scipy():
    result = paired_seed_test(REF, BASE)
    a, b = [10.0, 14.5, 9.0], [8.0, 11.0, 9.5]  # seeds 1, 2, 3 by hand
    expected = stats.ttest_rel(a, b)
    ci = expected.confidence_interval(0.95)
    assert result.n == "3 pairs"
    assert result.difference == pytest.approx(np.mean(np.subtract(a, b)))
    assert result.pvalue == pytest.approx(expected.pvalue)
    assert result.statistic == pytest.approx(expected.statistic)
    assert (result.ci_low, result.ci_high) == pytest.approx((ci.low, ci.high))
    # The CI of a paired mean difference by hand: mean +- t_{0.975, n-1} * sd / sqrt(n).
    d = np.subtract(a, b)
    half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d))
    assert (result.ci_low, result.ci_high) == pytest.approx((d.mean() - half, d.mean() + half))


def test_paired_test_needs_two_common_seeds():
    result = paired_seed_test({1: 1.0, 2: 2.0}, {2: 1.0, 3: 0.0})
    assert math.isnan(result.pvalue) and "2 seeds" in result.note and result.difference == 1.0


def test_welch_matches_scipy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(5, 1, 20), rng.normal(4, 3, 30)
    result = welch_episode_test(list(a), list(b))
    expected = stats.ttest_ind(a, b, equal_var=False)
    ci = expected.confidence_interval(0.95)
    assert result.n == "20 vs 30 episodes"
    assert result.difference == pytest.approx(a.mean() - b.mean())
    assert result.pvalue == pytest.approx(expected.pvalue)
    assert (result.ci_low, result.ci_high) == pytest.approx((ci.low, ci.high))


def test_constant_samples_give_no_pvalue_but_a_reason():
    result = welch_episode_test([0.0, 0.0, 0.0], [0.0, 0.0])
    assert math.isnan(result.pvalue) and result.note == "no variance"
    assert welch_episode_test(None, [1.0, 2.0]).note.startswith("final_eval.json without")


def _groups(tmp_path, make_run):
    ep = {
        1: ([10.0, 12.0, 14.0], [0.0, 4.0, 2.0]),
        2: ([20.0, 22.0, 18.0], [1.0, 1.0, 1.0]),
        3: ([5.0, 6.0, 7.0], [30.0, 20.0, 10.0]),
    }
    for seed, (rewards, costs) in ep.items():
        episodes = {"rewards": rewards, "costs": costs, "lengths": [50, 40, 30],
                    "safe_steps": [50, 30, 15]}
        make_run(tmp_path / f"s3rl{seed}", algo="s3rl", seed=seed, episodes=episodes)
        base = {**episodes, "rewards": [r - seed for r in rewards]}
        make_run(tmp_path / f"lag{seed}", algo="sac_lag", seed=seed, episodes=base)
    make_run(tmp_path / "s3rl4", algo="s3rl", seed=4, finished=False)
    groups = {g.algo: g for g in group_runs(find_runs(tmp_path))}
    return ep, groups


def test_summary_over_seeds_and_over_episodes(tmp_path, make_run):
    ep, groups = _groups(tmp_path, make_run)
    s = summarize(groups["s3rl"])
    assert s.seeds == (1, 2, 3)  # the unfinished seed 4 is left out
    per_seed = [np.mean(r) for r, _ in ep.values()]
    assert s.reward_seeds.mean == pytest.approx(np.mean(per_seed))
    assert s.reward_seeds.std == pytest.approx(np.std(per_seed, ddof=1))
    pooled_costs = np.concatenate([c for _, c in ep.values()])
    assert s.cost_episodes.mean == pytest.approx(pooled_costs.mean())
    assert s.cost_episodes.std == pytest.approx(pooled_costs.std())
    assert s.cost_episodes.n == 9
    # safe steps: 95 of 120 steps per seed
    assert s.safe_occupancy_seeds.mean == pytest.approx(100 * 95 / 120)
    assert s.length_seeds.mean == pytest.approx(40.0)
    mean_cost_seeds = np.mean([np.mean(c) for _, c in ep.values()])  # 2, 1, 20 -> 7.67
    assert s.over_limit == (mean_cost_seeds > 10.0) and not s.over_limit


def test_compare_groups_pairs_by_seed(tmp_path, make_run):
    ep, groups = _groups(tmp_path, make_run)
    paired, welch = compare_groups(groups["s3rl"], groups["sac_lag"], "reward")
    ref = [np.mean(r) for r, _ in ep.values()]
    base = [np.mean(r) - seed for seed, (r, _) in ep.items()]
    assert paired.pvalue == pytest.approx(stats.ttest_rel(ref, base).pvalue)
    assert paired.difference == pytest.approx(2.0)  # mean of seeds 1, 2, 3
    pooled_ref = np.concatenate([r for r, _ in ep.values()])
    pooled_base = np.concatenate([np.subtract(r, s) for s, (r, _) in ep.items()])
    expected = stats.ttest_ind(pooled_ref, pooled_base, equal_var=False)
    assert welch.pvalue == pytest.approx(expected.pvalue)
    assert welch.note == ""  # the seeds' episodes differ enough (share below, by hand)


def test_within_seed_share_by_hand_and_the_flag_on_copied_episodes(tmp_path, make_run):
    _, groups = _groups(tmp_path, make_run)
    # s3rl rewards: within-seed variances 8/3, 8/3, 2/3 (mean 2); the 9 pooled values have
    # mean 114/9 and mean square 1758/9.
    pooled = 1758 / 9 - (114 / 9) ** 2
    assert within_seed_share(groups["s3rl"].finished, "reward") == pytest.approx(2 / pooled)
    # A deterministic policy from a nearly fixed start: every episode of a seed the same
    # (SafetyBallRun-v0's final evaluations). The Welch test over 3 x 10 copies gives a small
    # p-value that the paired test over the 3 seeds does not; the table says so.
    for seed, reward, gap in ((1, 10.0, 9.0), (2, 30.0, 13.0), (3, 17.0, 5.0)):
        episodes = {"rewards": [reward] * 10, "costs": [1.0] * 10, "lengths": [50] * 10,
                    "safe_steps": [49] * 10}
        make_run(tmp_path / "copies" / f"s3rl{seed}", algo="s3rl", seed=seed, episodes=episodes)
        base = {**episodes, "rewards": [reward - gap] * 10}
        make_run(tmp_path / "copies" / f"lag{seed}", algo="sac_lag", seed=seed, episodes=base)
    copies = {g.algo: g for g in group_runs(find_runs(tmp_path / "copies"))}
    assert within_seed_share(copies["s3rl"].finished, "reward") == 0.0
    paired, welch = compare_groups(copies["s3rl"], copies["sac_lag"], "reward")
    assert "near copies" in welch.note and paired.note == ""
    assert welch.pvalue < 0.05 < paired.pvalue
    # costs: no variance at all, so no share and no flag (the test reports "no variance").
    assert math.isnan(within_seed_share(copies["s3rl"].finished, "cost"))
    _, welch_cost = compare_groups(copies["s3rl"], copies["sac_lag"], "cost")
    assert "near copies" not in welch_cost.note


def test_learning_curve_keeps_unfinished_runs(tmp_path, make_run):
    _, groups = _groups(tmp_path, make_run)
    frames, mean, std = learning_curve(groups["s3rl"], "eval/reward")
    assert list(frames) == [200, 400, 600]
    # seeds 1-4 at 200 and 400 frames (reward 1 + seed), seeds 1-3 at 600 (3 + seed)
    assert mean == pytest.approx([1 + 2.5, 2 + 2.5, 3 + 2.0])
    assert std == pytest.approx([np.std([1, 2, 3, 4])] * 2 + [np.std([1, 2, 3])])
    frames, mean, _ = learning_curve(groups["s3rl"], "probe/accuracy")
    assert list(frames) == [400, 600]  # NaN (first epoch) left out
