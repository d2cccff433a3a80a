"""Table 1's statistics: per-group summaries and the S3RL-vs-baseline tests (scipy.stats).

Two views of a group's final deterministic evaluation (``final_eval.json`` of finished runs):

* **over seeds**: one value per seed (that seed's mean over its evaluation episodes); mean and
  sample standard deviation (``ddof=1``) over seeds; compared with a **paired t-test** that
  pairs the two algorithms' runs by seed (only seeds present for both enter);
* **over episodes**: every evaluation episode of every seed pooled, as the paper's Table 1
  reports (mean +- std over the episodes of its evaluation); population std (``ddof=0``, as
  FSRL and ``final_eval.json``); compared with **Welch's t-test** (unequal variances).

Each test gives the difference of means (reference minus baseline), its 95% confidence
interval (``scipy``'s ``confidence_interval()`` of the test result) and the two-sided p-value.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from s3rl_torchrl.report.runs import Run, RunGroup

__all__ = [
    "MeanStd",
    "GroupSummary",
    "TestResult",
    "summarize",
    "paired_seed_test",
    "welch_episode_test",
    "compare_groups",
    "within_seed_share",
    "learning_curve",
]

#: final_eval.json key of the per-episode values of a metric (written since per-episode
#: values were added; older files only have the summary).
EPISODE_KEYS = {"reward": "episode_rewards", "cost": "episode_costs", "length": "episode_lengths"}
SUMMARY_KEYS = {"reward": "reward_mean", "cost": "cost_mean", "length": "length_mean"}


@dataclass(frozen=True)
class MeanStd:
    mean: float
    std: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float], ddof: int) -> MeanStd:
        values = np.asarray(values, dtype=float)
        if len(values) == 0:
            return cls(math.nan, math.nan, 0)
        std = float(np.std(values, ddof=ddof)) if len(values) > ddof else math.nan
        return cls(float(np.mean(values)), std, len(values))


@dataclass(frozen=True)
class GroupSummary:
    """A group's finished runs, summarised (see the module docstring for the two views)."""

    seeds: tuple[int, ...]
    reward_seeds: MeanStd
    cost_seeds: MeanStd
    length_seeds: MeanStd
    safe_occupancy_seeds: MeanStd  # percent of evaluation steps with zero cost
    reward_episodes: MeanStd  # NaN when a final_eval.json lacks per-episode values
    cost_episodes: MeanStd
    cost_limit: float

    @property
    def over_limit(self) -> bool:
        """The mean cost over seeds exceeds the task's cost limit."""
        return self.cost_seeds.mean > self.cost_limit


def seed_values(runs: Sequence[Run], metric: str) -> dict[int, float]:
    """seed -> that run's mean of ``metric`` over its final evaluation episodes."""
    key = SUMMARY_KEYS.get(metric, metric)
    return {r.seed: float(r.final[key]) for r in runs if r.finished}


def episode_values(runs: Sequence[Run], metric: str) -> list[float] | None:
    """Every final evaluation episode's ``metric``, pooled over runs (None if one lacks them)."""
    values: list[float] = []
    for run in runs:
        if not run.finished:
            continue
        episodes = run.final.get(EPISODE_KEYS[metric])
        if episodes is None:
            return None
        values.extend(float(v) for v in episodes)
    return values


def summarize(group: RunGroup) -> GroupSummary:
    runs = group.finished

    def over_episodes(metric: str) -> MeanStd:
        values = episode_values(runs, metric)
        return MeanStd.of(values, ddof=0) if values is not None else MeanStd(math.nan, math.nan, 0)

    return GroupSummary(
        seeds=tuple(r.seed for r in runs),
        reward_seeds=MeanStd.of(list(seed_values(runs, "reward").values()), ddof=1),
        cost_seeds=MeanStd.of(list(seed_values(runs, "cost").values()), ddof=1),
        length_seeds=MeanStd.of(list(seed_values(runs, "length").values()), ddof=1),
        safe_occupancy_seeds=MeanStd.of(
            list(seed_values(runs, "safe_occupancy").values()), ddof=1
        ),
        reward_episodes=over_episodes("reward"),
        cost_episodes=over_episodes("cost"),
        cost_limit=group.cost_limit,
    )


@dataclass(frozen=True)
class TestResult:
    """A two-sided t-test of ``mean(reference) - mean(baseline)``."""

    test: str
    n: str  # "3 pairs" or "20 vs 20 episodes"
    difference: float
    ci_low: float
    ci_high: float
    pvalue: float
    statistic: float
    note: str = ""

    @classmethod
    def not_run(cls, test: str, n: str, difference: float, note: str) -> TestResult:
        nan = math.nan
        return cls(test, n, difference, nan, nan, nan, nan, note)


def _run_test(test: str, n: str, difference: float, run) -> TestResult:
    # Samples without variance (e.g. every episode's cost is 0) have no t statistic: scipy
    # returns NaN with a RuntimeWarning; the table says why instead.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        result = run()
        ci = result.confidence_interval(0.95)
    # Equal non-zero differences give t = +-inf and p = 0 (scipy): kept, but flagged.
    note = "" if np.isfinite(result.statistic) else "no variance"
    return TestResult(
        test, n, difference, float(ci.low), float(ci.high), float(result.pvalue),
        float(result.statistic), note,
    )


def paired_seed_test(reference: dict[int, float], baseline: dict[int, float]) -> TestResult:
    """Paired t-test over the seeds both algorithms ran (``scipy.stats.ttest_rel``)."""
    seeds = sorted(set(reference) & set(baseline))
    a = np.array([reference[s] for s in seeds])
    b = np.array([baseline[s] for s in seeds])
    n = f"{len(seeds)} pair{'' if len(seeds) == 1 else 's'}"
    difference = float(np.mean(a - b)) if seeds else math.nan
    if len(seeds) < 2:
        return TestResult.not_run(
            "paired t (seeds)", n, difference, "needs >= 2 seeds run by both"
        )
    return _run_test("paired t (seeds)", n, difference, lambda: stats.ttest_rel(a, b))


def welch_episode_test(
    reference: Sequence[float] | None, baseline: Sequence[float] | None
) -> TestResult:
    """Welch's t-test over pooled evaluation episodes (``ttest_ind(equal_var=False)``)."""
    if reference is None or baseline is None:
        return TestResult.not_run(
            "Welch t (episodes)", "-", math.nan, "final_eval.json without per-episode values"
        )
    a, b = np.asarray(reference, dtype=float), np.asarray(baseline, dtype=float)
    n = f"{len(a)} vs {len(b)} episodes"
    difference = float(a.mean() - b.mean()) if len(a) and len(b) else math.nan
    if min(len(a), len(b)) < 2:
        return TestResult.not_run("Welch t (episodes)", n, difference, "needs >= 2 episodes each")
    return _run_test(
        "Welch t (episodes)", n, difference, lambda: stats.ttest_ind(a, b, equal_var=False)
    )


#: Below this share of the pooled variance coming from within seeds, a seed's episodes are
#: near copies of one another (a deterministic policy from an almost fixed start state), so
#: pooling them multiplies one sample per seed and the Welch test's p-value is far too small.
WITHIN_SEED_SHARE_MIN = 0.05


def within_seed_share(runs: Sequence[Run], metric: str) -> float:
    """Mean over seeds of the variance of a seed's episodes, over the variance of all the
    episodes pooled (1: seeds alike, 0: each seed's episodes identical); NaN without
    per-episode values or without any variance."""
    per_seed = []
    for run in runs:
        episodes = run.final.get(EPISODE_KEYS[metric]) if run.finished else None
        if episodes:
            per_seed.append(np.asarray(episodes, dtype=float))
    if not per_seed:
        return math.nan
    pooled = np.concatenate(per_seed).var()
    if pooled == 0:
        return math.nan
    return float(np.mean([e.var() for e in per_seed]) / pooled)


def compare_groups(
    reference: RunGroup, baseline: RunGroup, metric: str
) -> tuple[TestResult, TestResult]:
    """(paired over seeds, Welch over episodes) of ``metric`` ("reward" or "cost"). The Welch
    result is flagged when a group's episodes vary almost only between seeds
    (``WITHIN_SEED_SHARE_MIN``): then only the test over seeds means anything."""
    ref_runs, base_runs = reference.finished, baseline.finished
    welch = welch_episode_test(episode_values(ref_runs, metric), episode_values(base_runs, metric))
    shares = [within_seed_share(runs, metric) for runs in (ref_runs, base_runs)]
    if any(share < WITHIN_SEED_SHARE_MIN for share in shares):  # NaN compares False
        note = "episodes of a seed near copies, not independent: use the test over seeds"
        welch = replace(welch, note=f"{welch.note}; {note}" if welch.note else note)
    return (
        paired_seed_test(seed_values(ref_runs, metric), seed_values(base_runs, metric)),
        welch,
    )


def learning_curve(group: RunGroup, column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frames, mean over seeds, std over seeds) of a metrics.csv column, every run included.

    At each frame count the runs that logged it enter (an unfinished run stops adding points
    where it stopped); the std is over those runs (``ddof=0``, 0 for one run); NaN values
    (e.g. the probe before both classes exist) are left out (:meth:`Run.column`).
    """
    by_frames: dict[float, list[float]] = {}
    for run in group.runs:
        for frames, value in zip(*run.column(column)):
            by_frames.setdefault(frames, []).append(value)
    frames = np.array(sorted(by_frames))
    mean = np.array([np.mean(by_frames[f]) for f in frames])
    std = np.array([np.std(by_frames[f]) for f in frames])
    return frames, mean, std
