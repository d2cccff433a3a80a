"""One answer across tasks: ``s3rl-report``'s aggregate section, built on ``rliable``.

Each finished run gives one number per statistic (its final evaluation's mean over episodes,
``final_eval.json``), read under both evaluation protocols (``runs.PROTOCOLS``: the last policy
and the best-feasible checkpoint). Per algo (a report group's label), pooled over the tasks it
ran and their seeds:

* the **interquartile mean** (IQM: the mean of the middle 50% of the runs, rliable's
  ``metrics.aggregate_iqm``) of ``cost / cost limit`` (lower is better, 1 = at the limit) and of
  the **normalised reward** (below);
* the **share of runs within the limit** (mean cost <= the task's cost limit);
* the **probability of improvement** of one algo over another (rliable's
  ``metrics.probability_of_improvement``; its resamples with the same statistic in numpy): for
  each task both ran, the probability that a run of the first beats a run of the second (the
  Mann-Whitney U statistic over all pairs of runs; ties count one half), averaged over those
  tasks; for the cost, beating is a *lower* cost; the report also lists each task's term of
  that average (which tasks the answer comes from);
* **performance profiles**: the fraction of runs whose normalised reward is above each
  threshold, and the fraction whose ``cost / limit`` is at or below each threshold (at 1: the
  share within the limit).

Intervals are 95% percentile intervals of rliable's stratified bootstrap
(``library.get_interval_estimates`` with one array per task, each resampled with replacement
within the task: ``StratifiedIndependentBootstrap``, its draw made cheaper by
``_stratified_bootstrap``). rliable 1.2.0 draws its resamples from
NumPy's global generator (``np.random.choice``; its ``random_state`` argument does not reach
them), so every estimate is computed with that generator seeded (``seed``) and restored after:
a report rebuilt from the same runs prints the same intervals.

**Normalised reward**, per task: ``(reward - floor) / (top - floor)``. *top* is the best
reward any final evaluation of the task reached within the cost limit (any algo, seed and
protocol in the report): 1 is the best safe policy found, above 1 more reward than that, bought
with cost. *floor* is the lowest evaluation reward any run of the task logged, its training
curve (``metrics.csv``'s ``eval/reward``, every epoch) included: a policy that has not learned
the task, or has unlearned it, scores about 0. The usual floor is the random policy's reward, but
``final_eval.json`` does not keep it (the trainer only prints the random-policy row). Two
stand-ins the files allow were set aside: the first logged evaluation (the barely trained
policy) can be above every safe final reward (results/safe, SafetyBallRun-v0: that policy runs
fast and unsafe); and the lowest *final* reward (min-max over the final evaluations) scores a
run that learned the task as 0 whenever it is the worst of a narrow spread (results/safe,
HalfCheetah: every final reward within 20% of the best). Both anchors come from the reported runs, so scores compare
algos within one report, not across reports.

Needs the ``report`` extra (``pip install "s3rl-torchrl[report]"``); this module imports
without it and says so when asked for the aggregate.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.runs import PROTOCOLS, RunGroup, under_protocol

__all__ = [
    "AGGREGATE_FIGURE",
    "INSTALL_HINT",
    "Aggregate",
    "Anchors",
    "Estimate",
    "ProtocolAggregate",
    "RunScores",
    "aggregate",
    "aggregate_section",
    "bootstrap",
    "interquartile_mean",
    "performance_profile",
    "performance_profiles_figure",
    "probability_of_improvement",
    "probability_of_improvement_by_task",
    "reward_anchors",
    "rliable_problem",
    "run_scores",
    "share",
]

INSTALL_HINT = 'pip install "s3rl-torchrl[report]"'
DEFAULT_REPS = 2000
DEFAULT_SEED = 0
CONFIDENCE = 0.95
AGGREGATE_FIGURE = "aggregate_performance_profiles"
PROFILE_POINTS = 101


def rliable_problem() -> str | None:
    """None when rliable imports, else why not and what to install."""
    try:
        from rliable import library, metrics  # noqa: F401
    except ImportError as err:
        return f"rliable is not installed ({err}): {INSTALL_HINT}"
    except Exception as err:  # e.g. arch 7.2 under pandas 3: a TypeError at import
        return (
            f"rliable is installed but does not import ({type(err).__name__}: {err}); install "
            f"the pinned versions (rliable 1.2.0, arch 7.x, pandas < 3): "
            f"pip install -c constraints.txt \"s3rl-torchrl[report]\""
        )
    return None


# ------------------------------------------------------------------------------ the estimates
@dataclass(frozen=True)
class Estimate:
    """A point estimate and its 95% stratified-bootstrap interval."""

    point: float
    low: float
    high: float

    def cell(self, digits: int = 2) -> str:
        if math.isnan(self.point):
            return "–"
        return f"{self.point:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"


@contextlib.contextmanager
def _global_seed(seed: int) -> Iterator[None]:
    """NumPy's global generator seeded inside the block (rliable 1.2.0 resamples with
    ``np.random.choice``), its previous state restored after."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def _columns(per_task: Mapping[str, np.ndarray]) -> list[np.ndarray]:
    """One (runs, 1) array per task, in task order: the strata of the bootstrap."""
    return [np.asarray(per_task[task], dtype=float).reshape(-1, 1) for task in sorted(per_task)]


def bootstrap(
    func: Callable[..., np.ndarray],
    strata: Sequence[np.ndarray],
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(point, low, high) of ``func(*strata)`` (a 1-D array) with rliable's stratified
    bootstrap: each stratum (a task's runs, shape (runs, 1)) resampled with replacement on its
    own, ``reps`` times; 95% percentile interval."""
    strata = list(strata)
    # What library.get_interval_estimates does with a list of arrays, with its bootstrap's
    # per-stratum draw made cheaper (_stratified_bootstrap).
    with _global_seed(seed):
        resampler = _stratified_bootstrap()(*strata)
        point = np.atleast_1d(np.asarray(func(*strata), dtype=float))
        interval = resampler.conf_int(func, reps=reps, size=CONFIDENCE, method="percentile")
    interval = np.asarray(interval, dtype=float).reshape(2, -1)
    return point, interval[0], interval[1]


@functools.cache
def _stratified_bootstrap() -> type:
    """rliable's ``StratifiedIndependentBootstrap`` drawing each stratum's resample with
    ``np.random.randint(0, n, shape)`` instead of ``np.random.choice(n, shape)``: NumPy's legacy
    generator makes the one by calling the other (sampling with replacement, no weights), so the
    draws, and every interval, are rliable's; ``choice``'s argument checks cost more than the
    draw itself, once per task per resample (with ``choice``, about half of the bootstrap's time
    on Table 1's 16 tasks: research/2026-11-21-benchmark-studies.md).
    tests/report/test_aggregate.py holds it to ``library.get_interval_estimates``."""
    from rliable import library

    class StratifiedBootstrap(library.StratifiedIndependentBootstrap):
        def _get_indices(self, num_runs, array_shape, strata_indices):
            return (np.random.randint(0, num_runs, array_shape), *strata_indices)

    return StratifiedBootstrap


def _scalar(func: Callable[..., float], per_task: Mapping[str, np.ndarray], reps: int,
            seed: int) -> Estimate:
    if not per_task:
        return Estimate(math.nan, math.nan, math.nan)
    point, low, high = bootstrap(lambda *cols: np.array([func(*cols)]), _columns(per_task),
                                 reps, seed)
    return Estimate(float(point[0]), float(low[0]), float(high[0]))


def interquartile_mean(
    per_task: Mapping[str, np.ndarray], reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> Estimate:
    """IQM over every run of every task (rliable's ``aggregate_iqm``: the 25%-trimmed mean,
    ``scipy.stats.trim_mean``), with its interval. ``per_task``: task -> one value per run."""
    from rliable import metrics

    return _scalar(lambda *cols: metrics.aggregate_iqm(np.concatenate(cols)), per_task, reps,
                   seed)


def share(
    per_task: Mapping[str, np.ndarray], reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> Estimate:
    """The mean over every run of every task (of 0/1 values: the share of runs where it holds),
    with its interval."""
    return _scalar(lambda *cols: float(np.mean(np.concatenate(cols))), per_task, reps, seed)


def _improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) from all pairs of runs, ties one half: rliable's per-task
    ``probability_of_improvement`` (the Mann-Whitney U statistic / (runs of X x runs of Y)),
    vectorised for the bootstrap's resamples (scipy's ``mannwhitneyu`` per resample is most of
    a report's time); the tests check the two agree. The counts divided as ``np.mean`` of a
    boolean array divides its exact sum: the same floats, at a third of ``np.mean``'s cost."""
    d = x.reshape(-1, 1) - y.reshape(1, -1)
    pairs = d.size
    return np.count_nonzero(d > 0) / pairs + 0.5 * (np.count_nonzero(d == 0) / pairs)


def probability_of_improvement_by_task(
    x: Mapping[str, np.ndarray], y: Mapping[str, np.ndarray], lower_is_better: bool = False
) -> dict[str, float]:
    """Per task both ran, in task order: P(a run of X beats a run of Y), rliable's
    ``probability_of_improvement`` (Mann-Whitney U / (runs of X x runs of Y), ties one half).
    Their mean is the aggregate's point estimate; the table of them says which tasks it comes
    from."""
    from rliable import metrics

    sign = -1.0 if lower_is_better else 1.0
    tasks = sorted(set(x) & set(y))
    # rliable takes (runs x tasks) matrices: one column, one task.
    return {t: float(metrics.probability_of_improvement(sign * xs, sign * ys))
            for t, xs, ys in zip(tasks, _columns({t: x[t] for t in tasks}),
                                 _columns({t: y[t] for t in tasks}))}


def probability_of_improvement(
    x: Mapping[str, np.ndarray],
    y: Mapping[str, np.ndarray],
    lower_is_better: bool = False,
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> tuple[Estimate, list[str]]:
    """P(a run of X beats a run of Y), per task (rliable's ``probability_of_improvement``:
    Mann-Whitney U / (runs of X x runs of Y), ties one half), averaged over the tasks both ran;
    X's and Y's runs resampled independently within each task. Returns the estimate and those
    tasks."""
    tasks = sorted(set(x) & set(y))
    if not tasks:
        return Estimate(math.nan, math.nan, math.nan), []
    sign = -1.0 if lower_is_better else 1.0
    strata = [sign * c for c in _columns({t: x[t] for t in tasks})]
    strata += [sign * c for c in _columns({t: y[t] for t in tasks})]
    k = len(tasks)

    def func(*cols: np.ndarray) -> np.ndarray:
        return np.array([np.mean([_improvement(cols[i], cols[k + i]) for i in range(k)])])

    _, low, high = bootstrap(func, strata, reps, seed)
    # The point estimate from rliable itself.
    point = np.mean(list(probability_of_improvement_by_task(x, y, lower_is_better).values()))
    return Estimate(float(point), float(low[0]), float(high[0])), tasks


def performance_profile(
    per_task: Mapping[str, np.ndarray],
    taus: np.ndarray,
    at_most: bool = False,
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(profile, low, high) at each threshold of ``taus``: the fraction of runs (all tasks
    pooled) whose value is above it (rliable's run score distribution, ``create_performance_
    profile``'s default, vectorised over the thresholds), or, with ``at_most``, at or below it
    (for costs); with its pointwise interval."""
    taus = np.asarray(taus, dtype=float)

    def func(*cols: np.ndarray) -> np.ndarray:
        runs = np.concatenate(cols).ravel()[:, None]
        return (runs <= taus[None, :] if at_most else runs > taus[None, :]).mean(axis=0)

    return bootstrap(func, _columns(per_task), reps, seed)


# ------------------------------------------------------------------------------ the runs
@dataclass(frozen=True)
class Anchors:
    """A task's reward normalisation: ``(reward - floor) / (top - floor)``."""

    task: str
    cost_limit: float
    floor: float  # the lowest evaluation reward any run of the task logged, curves included
    top: float  # the best final reward within the limit; NaN if no final evaluation is
    floor_from: str = ""  # which evaluation gave each anchor
    top_from: str = ""

    @property
    def usable(self) -> bool:
        return not math.isnan(self.top) and self.top > self.floor

    def normalise(self, reward: np.ndarray | float) -> np.ndarray:
        return (np.asarray(reward, dtype=float) - self.floor) / (self.top - self.floor)


def _evaluations(group: RunGroup):
    """(protocol, run) for every finished run of ``group`` under every protocol it has."""
    for protocol in PROTOCOLS:
        read = under_protocol(group, protocol)
        if read is not None:
            for run in read.finished:
                yield protocol, run


def _frames(frames: float) -> str:
    return f"{frames / 1e6:g}M" if frames >= 1e6 else f"{frames / 1e3:g}k"


def reward_anchors(groups: Sequence[RunGroup]) -> dict[str, Anchors]:
    """Each task's anchors: *top* from every final evaluation of it (all groups, seeds and
    protocols), *floor* from those and every run's logged evaluations (``eval/reward``)."""
    finals: dict[str, list] = {}
    logged: dict[str, list] = {}
    limits: dict[str, float] = {}
    for group in groups:
        limits.setdefault(group.task, group.cost_limit)
        for protocol, run in _evaluations(group):
            finals.setdefault(group.task, []).append((
                float(run.final["reward_mean"]), float(run.final["cost_mean"]) <= group.cost_limit,
                f"{group.label} seed {run.seed}, {PROTOCOLS[protocol]}"))
        for run in group.runs:
            for frames, reward in zip(*run.column("eval/reward")):
                logged.setdefault(group.task, []).append(
                    (reward, f"{group.label} seed {run.seed}, {_frames(frames)} frames"))
    anchors = {}
    for task in sorted(finals):
        floor, floor_from = min([(r, w) for r, _, w in finals[task]] + logged.get(task, []),
                                key=lambda x: x[0])
        # the feasible flag is False for a NaN limit: no top, the task is left out
        feasible = [(r, w) for r, within, w in finals[task] if within]
        top, top_from = max(feasible, key=lambda x: x[0]) if feasible else (math.nan, "")
        anchors[task] = Anchors(task, limits[task], floor, top, floor_from, top_from)
    return anchors


@dataclass
class RunScores:
    """One algo's runs of one task under one protocol: one entry per seed."""

    seeds: list[int]
    reward: np.ndarray
    cost: np.ndarray
    cost_limit: float

    @property
    def cost_ratio(self) -> np.ndarray:
        return self.cost / self.cost_limit

    @property
    def within(self) -> np.ndarray:
        return (self.cost <= self.cost_limit).astype(float)


def run_scores(groups: Sequence[RunGroup], protocol: str) -> dict[str, dict[str, RunScores]]:
    """label -> task -> its finished runs' final evaluation under ``protocol``."""
    scores: dict[str, dict[str, RunScores]] = {}
    for group in groups:
        read = under_protocol(group, protocol)
        if read is None or not read.finished:
            continue
        runs = read.finished
        scores.setdefault(group.label, {})[group.task] = RunScores(
            [r.seed for r in runs],
            np.array([float(r.final["reward_mean"]) for r in runs]),
            np.array([float(r.final["cost_mean"]) for r in runs]),
            group.cost_limit,
        )
    return scores


# ------------------------------------------------------------------------------ the aggregate
@dataclass
class AlgoRow:
    label: str
    tasks: int
    runs: int
    cost_ratio: Estimate
    normalised_reward: Estimate
    reward_tasks: int  # tasks with usable anchors
    within: Estimate
    within_count: tuple[int, int]  # (runs within the limit, runs judged)


@dataclass
class PairRow:
    first: str
    second: str
    tasks: list[str]
    runs: tuple[int, int]
    cost: Estimate  # P(first's cost < second's)
    reward: Estimate  # P(first's reward > second's)
    # The same per task (their means are the point estimates above).
    cost_by_task: dict[str, float] = field(default_factory=dict)
    reward_by_task: dict[str, float] = field(default_factory=dict)


@dataclass
class ProtocolAggregate:
    protocol: str  # a PROTOCOLS key
    algos: list[AlgoRow]
    pairs: list[PairRow]
    # label -> (normalised reward per task, cost / limit per task): the profiles' data
    profile_data: dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray]]]


@dataclass
class Aggregate:
    anchors: dict[str, Anchors]
    protocols: list[ProtocolAggregate]
    notes: list[str] = field(default_factory=list)
    algos: dict[str, str] = field(default_factory=dict)  # label -> algo, the reference first
    reps: int = DEFAULT_REPS
    seed: int = DEFAULT_SEED


def _pairs(
    groups: Sequence[RunGroup], reference: str, pairs: Sequence[tuple[str, str]]
) -> list[tuple[str, str]]:
    """(first label, second label): every group of the reference algo against every group of
    another algo, then the ``--compare`` pairs (names: algos or labels), without repeats."""
    labels: dict[str, str] = {}
    for group in groups:
        labels.setdefault(group.label, group.algo)
    out = [(a, b) for a, algo_a in labels.items() if algo_a == reference
           for b, algo_b in labels.items() if algo_b != reference]
    for first, second in pairs:
        for a, algo_a in labels.items():
            for b, algo_b in labels.items():
                if a != b and first in (a, algo_a) and second in (b, algo_b) and (a, b) not in out:
                    out.append((a, b))
    return out


def _protocol_aggregate(
    groups: Sequence[RunGroup],
    protocol: str,
    anchors: Mapping[str, Anchors],
    compared: Sequence[tuple[str, str]],
    reps: int,
    seed: int,
) -> ProtocolAggregate | None:
    scores = run_scores(groups, protocol)
    if not scores:
        return None
    algos, profile_data = [], {}
    for label, tasks in scores.items():
        judged = {t: s for t, s in tasks.items() if s.cost_limit > 0}  # False for NaN
        ratio = {t: s.cost_ratio for t, s in judged.items()}
        within = {t: s.within for t, s in judged.items()}
        normalised = {t: anchors[t].normalise(s.reward) for t, s in tasks.items()
                      if anchors[t].usable}
        algos.append(AlgoRow(
            label, len(tasks), sum(len(s.seeds) for s in tasks.values()),
            interquartile_mean(ratio, reps, seed), interquartile_mean(normalised, reps, seed),
            len(normalised), share(within, reps, seed),
            (int(sum(w.sum() for w in within.values())), sum(len(w) for w in within.values())),
        ))
        profile_data[label] = (normalised, ratio)
    rows = []
    for first, second in compared:
        if first not in scores or second not in scores:
            continue
        x, y = scores[first], scores[second]
        x_cost, y_cost = ({t: s.cost for t, s in z.items()} for z in (x, y))
        x_reward, y_reward = ({t: s.reward for t, s in z.items()} for z in (x, y))
        cost, tasks = probability_of_improvement(x_cost, y_cost, lower_is_better=True,
                                                 reps=reps, seed=seed)
        if not tasks:
            continue
        reward, _ = probability_of_improvement(x_reward, y_reward, reps=reps, seed=seed)
        runs = (sum(len(x[t].seeds) for t in tasks), sum(len(y[t].seeds) for t in tasks))
        rows.append(PairRow(
            first, second, tasks, runs, cost, reward,
            probability_of_improvement_by_task(x_cost, y_cost, lower_is_better=True),
            probability_of_improvement_by_task(x_reward, y_reward)))
    return ProtocolAggregate(protocol, algos, rows, profile_data)


def aggregate(
    groups: Sequence[RunGroup],
    reference: str = "s3rl",
    pairs: Sequence[tuple[str, str]] = (),
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> Aggregate:
    """Every statistic of the module docstring, for each protocol the runs were evaluated
    with. Needs rliable."""
    problem = rliable_problem()
    if problem is not None:
        raise ImportError(problem)
    groups = sorted(groups, key=lambda g: (g.algo != reference, g.label, g.task))
    anchors = reward_anchors(groups)
    labels = {g.label: g.algo for g in sorted(groups, key=lambda g: (g.algo != reference,
                                                                      g.label))}
    result = Aggregate(anchors, [], algos=labels, reps=reps, seed=seed)
    for task, anchor in anchors.items():
        if not anchor.usable:
            why = ("no evaluation of it is within the cost limit" if math.isnan(anchor.top)
                   else "its best reward within the limit is also its lowest reward")
            result.notes.append(f"Aggregate: {task} is left out of the normalised reward: {why}.")
        if not anchor.cost_limit > 0:
            result.notes.append(f"Aggregate: {task} has no positive cost limit "
                                f"({anchor.cost_limit:g}): left out of cost / limit and the "
                                "share within the limit.")
    compared = _pairs(groups, reference, pairs)
    for protocol in PROTOCOLS:
        read = _protocol_aggregate(groups, protocol, anchors, compared, reps, seed)
        if read is not None:
            result.protocols.append(read)
    task_sets = {label: sorted({g.task for g in groups if g.label == label and g.finished})
                 for label in result.algos}
    if len({tuple(tasks) for tasks in task_sets.values() if tasks}) > 1:
        result.notes.append(
            "Aggregate: the algos ran different tasks ("
            + "; ".join(f"{label}: {', '.join(tasks)}" for label, tasks in task_sets.items()
                        if tasks)
            + "): compare their IQMs and shares only where the tasks match; a probability of "
            "improvement is over the tasks both algos ran.")
    for label in result.algos:
        counts = {len(g.finished) for g in groups if g.label == label and g.finished}
        if len(counts) > 1:
            result.notes.append(
                f"Aggregate: {label} has different numbers of finished seeds per task "
                f"({', '.join(str(c) for c in sorted(counts))}): its pooled statistics weigh a "
                "task by its number of runs.")
    return result


# ------------------------------------------------------------------------------ the report
def _table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str) -> list[str]:
    sep = ["---:" if a == "r" else "---" for a in align]
    return ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |",
            *["| " + " | ".join(row) + " |" for row in rows]]


def _anchor_table(anchors: Mapping[str, Anchors]) -> list[str]:
    rows = []
    for task, a in anchors.items():
        top = "– (none within the limit)" if math.isnan(a.top) else f"{a.top:.2f} ({a.top_from})"
        rows.append([task, f"{a.cost_limit:g}", f"{a.floor:.2f} ({a.floor_from})", top])
    return _table(["task", "cost limit", "floor: lowest logged reward",
                   "top: best final reward within the limit"], rows, "lrll")


def _protocol_lines(read: ProtocolAggregate) -> list[str]:
    lines = [f"### {PROTOCOLS[read.protocol][0].upper()}{PROTOCOLS[read.protocol][1:]}", ""]
    rows = []
    for row in read.algos:
        within, judged = row.within_count
        rows.append([
            row.label, str(row.tasks), str(row.runs), row.cost_ratio.cell(),
            row.normalised_reward.cell() + (
                f" ({row.reward_tasks} tasks)" if row.reward_tasks != row.tasks else ""),
            f"{row.within.cell()} ({within} of {judged})",
        ])
    lines += _table(["algo", "tasks", "runs", "IQM cost / limit", "IQM normalised reward",
                     "share within the limit"], rows, "lrrrrr")
    lines.append("")
    if read.pairs:
        rows = [[f"{p.first} over {p.second}", ", ".join(p.tasks), f"{p.runs[0]} vs {p.runs[1]}",
                 p.cost.cell(), p.reward.cell()] for p in read.pairs]
        lines += _table(["probability of improvement", "tasks", "runs", "P(lower cost)",
                         "P(higher reward)"], rows, "llrrr")
        lines += ["", "Per task (all pairs of the two algos' runs; their mean over the tasks is the "
                  "estimate above):", ""]
        rows = [[f"{p.first} over {p.second}", task, f"{p.cost_by_task[task]:.2f}",
                 f"{p.reward_by_task[task]:.2f}"] for p in read.pairs for task in p.tasks]
        lines += _table(["probability of improvement", "task", "P(lower cost)",
                         "P(higher reward)"], rows, "llrr")
    else:
        lines.append("No two compared algos ran a common task: no probability of improvement.")
    lines.append("")
    return lines


def aggregate_section(
    groups: Sequence[RunGroup],
    out_dir: Path,
    reference: str = "s3rl",
    pairs: Sequence[tuple[str, str]] = (),
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> tuple[list[str], list[Path], list[str]]:
    """(report.md lines, figure files, notes) of the aggregate section. Without rliable: the
    section says what to install, and a note too."""
    lines = ["## Aggregate over tasks (rliable)", ""]
    problem = rliable_problem()
    if problem is not None:
        return [*lines, f"Not computed: {problem}.", ""], [], [f"Aggregate not computed: {problem}."]
    if not any(g.finished for g in groups):
        return [*lines, "No finished run.", ""], [], []
    result = aggregate(groups, reference, pairs, reps, seed)
    lines += [
        "One answer across tasks and seeds (module `s3rl_torchrl.report.aggregate`; "
        "[rliable](https://github.com/google-research/rliable)). One value per finished run: its "
        "final evaluation's mean over episodes. *IQM*: interquartile mean over all runs of all "
        "the algo's tasks (the mean of the middle 50%). *cost / limit*: lower is better, 1 is "
        "at the limit. *normalised reward*: per task, (reward − floor) / (top − floor), with "
        "*top* the best reward any final evaluation of the task reached within the cost limit "
        "(any algo, seed or protocol here: 1 is the best safe policy found, above 1 more reward "
        "than that, bought with cost) and *floor* the lowest evaluation reward any run of the "
        "task logged, training curves included (about 0: a policy that has not learned the "
        "task; `final_eval.json` keeps no random-policy reward to anchor 0 on). *share within the "
        "limit*: runs whose mean cost is at most the limit. *probability of improvement* of A "
        "over B: per task both ran, the chance that a run of A beats a run of B (lower cost; "
        "higher reward; ties count one half), averaged over those tasks; 0.5 is no difference. "
        f"[low, high]: {CONFIDENCE:.0%} percentile interval of the stratified bootstrap (runs "
        f"resampled within each task; {result.reps} resamples, NumPy seed {result.seed}, so "
        "a rebuild prints the same intervals). With few seeds per task the intervals are wide: "
        "read them, not the point estimates. An interval of zero width says that resampling "
        "within tasks cannot move the estimate (e.g. each task's runs all within the limit or "
        "all over it), not that it is certain.",
        "",
        "Normalisation anchors:",
        "",
        *_anchor_table(result.anchors),
        "",
    ]
    for read in result.protocols:
        lines += _protocol_lines(read)
    figures = performance_profiles_figure(result, out_dir, reference)
    lines += [
        "Performance profiles: the fraction of runs whose normalised reward is above each "
        "threshold (left) and whose cost / limit is at or below it (right; at 1 the share "
        f"within the limit), all tasks pooled; shaded: pointwise {CONFIDENCE:.0%} interval.",
        "",
        f"![Aggregate performance profiles]({AGGREGATE_FIGURE}.png)",
        "",
    ]
    return lines, figures, result.notes


def _grid(values: list[np.ndarray], low: float, high: float) -> np.ndarray:
    finite = [v[np.isfinite(v)] for v in values if v.size]
    pooled = np.concatenate(finite) if finite else np.array([])
    if pooled.size:
        low, high = min(low, float(pooled.min())), max(high, float(pooled.max()))
    return np.linspace(low, high, PROFILE_POINTS)


def performance_profiles_figure(result: Aggregate, out_dir: Path, reference: str) -> list[Path]:
    """One row per protocol: the normalised-reward profile (fraction of runs above each
    threshold) and the cost / limit profile (fraction at or below), with bootstrap bands."""
    from s3rl_torchrl.report.figures import _colours, _pyplot, _save

    plt = _pyplot()
    reads = result.protocols
    labels = [label for label in result.algos
              if any(label in read.profile_data for read in reads)]
    colours = _colours(labels, reference)
    all_data = [d for read in reads for d in read.profile_data.values()]
    reward_taus = _grid([v for n, _ in all_data for v in n.values()], 0.0, 1.0)
    cost_taus = _grid([v for _, r in all_data for v in r.values()], 0.0, 1.0)
    fig, axes = plt.subplots(len(reads), 2, figsize=(11.0, 3.8 * len(reads)), squeeze=False)
    for row, read in enumerate(reads):
        for col, (taus, at_most) in enumerate(((reward_taus, False), (cost_taus, True))):
            ax = axes[row, col]
            for label in labels:
                if label not in read.profile_data:
                    continue
                data = read.profile_data[label][col]
                if not data:
                    continue
                profile, low, high = performance_profile(data, taus, at_most, result.reps,
                                                         result.seed)
                ax.step(taus, profile, where="post", color=colours[label], label=label)
                ax.fill_between(taus, low, high, step="post", color=colours[label], alpha=0.2,
                                lw=0)
            ax.axvline(1.0, color="black", ls="--", lw=1)
            ax.set_ylim(-0.02, 1.02)
            ax.set_xlabel("normalised reward τ" if col == 0 else "cost / limit τ")
            ax.set_ylabel("fraction of runs with score > τ" if col == 0
                          else "fraction of runs with cost / limit ≤ τ")
            ax.set_title(PROTOCOLS[read.protocol], fontsize=10)
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8)
    fig.suptitle(f"Performance profiles over tasks and seeds ({CONFIDENCE:.0%} stratified "
                 "bootstrap bands)")
    fig.tight_layout()
    paths = _save(fig, out_dir, AGGREGATE_FIGURE)
    plt.close(fig)
    return paths
