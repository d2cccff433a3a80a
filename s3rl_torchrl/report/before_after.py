"""Before / after: the same tasks, algos and seeds trained under two presets, paired per seed.

``s3rl-report before-after --before OLD... --after NEW...`` reads two sets of result trees
(e.g. ``results/safe_sound results/table1`` against ``results/table1_v2``) and, per task and
algo, puts each seed's final evaluation under the old preset beside the same seed's under the
new one: mean reward and cost, the runs within the limit, a paired t-test per task (reward and
cost, over the seeds both ran), and the share of the old reward the new preset keeps. Its
``targets`` are the questions a change of preset has to answer (one row each, met or not): how
many runs deliver a policy within the limit under each preset, whether the new preset keeps at
least ``reward_kept`` of the old reward wherever the old one held its limit, whether its runs
still move (none buys its cost by giving up the task it had learned: see :class:`Stop`), and,
per named task, whether the new mean reward and cost reach a bar.

A run is within its limit when its final evaluation's mean cost is at most the run's
``task.cost_limit`` (the limit it trained for: 10, or 25 on SafetyPointGoal1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from s3rl_torchrl.envs.registry import TASKS
from s3rl_torchrl.report.runs import (
    PROTOCOLS,
    ReportError,
    Run,
    final_evaluation,
    picked_candidate,
    runs_by_key,
)
from s3rl_torchrl.report.stats import TestResult, paired_seed_test

__all__ = [
    "TARGET_KINDS", "BeforeAfter", "Miss", "SeedPair", "Stop", "Target", "TaskRow", "before_after",
    "write_markdown",
]


@dataclass(frozen=True)
class SeedPair:
    """One seed's final evaluation (mean over its episodes) under each preset, and its training
    reward (``train/reward`` over the last 20% of epochs; NaN where a run did not log it)."""

    seed: int
    before_reward: float
    before_cost: float
    after_reward: float
    after_cost: float
    before_training_reward: float = math.nan
    after_training_reward: float = math.nan


@dataclass
class TaskRow:
    """One task and algo: the seeds both presets ran to the end."""

    task: str
    algo: str
    cost_limit: float
    pairs: list[SeedPair]
    reward_test: TestResult = field(init=False)
    cost_test: TestResult = field(init=False)

    def __post_init__(self) -> None:
        def by_seed(name: str) -> dict[int, float]:
            return {p.seed: getattr(p, name) for p in self.pairs}

        # after - before: a negative cost difference is a safer new preset.
        self.reward_test = paired_seed_test(by_seed("after_reward"), by_seed("before_reward"))
        self.cost_test = paired_seed_test(by_seed("after_cost"), by_seed("before_cost"))

    def mean(self, name: str) -> float:
        return float(np.mean([getattr(p, name) for p in self.pairs]))

    def within(self, side: str) -> int:
        """Runs whose ``side`` ("before" or "after") cost is within the limit."""
        return sum(getattr(p, f"{side}_cost") <= self.cost_limit for p in self.pairs)

    def kept(self, name: str = "reward") -> float:
        """New mean of ``name`` (``reward`` or ``training_reward``) over the old one (NaN when the
        old one is not positive)."""
        before = self.mean(f"before_{name}")
        return self.mean(f"after_{name}") / before if before > 0 else math.nan

    @property
    def reward_kept(self) -> float:
        return self.kept("reward")


#: Why a run is over its limit under the new preset, as :attr:`Miss.cause` reads its files: its
#: last policy's training cost (what the multiplier held) within the limit or over it; for a pick,
#: whether any kept policy was within the limit on the picking episodes.
MISS_CAUSES = {
    "training_within": "training cost within the limit",
    "training_over": "training cost over it",
    "pick_none_within": "no kept policy within",
    "pick_reported_over": "pick within on its own episodes",
}


@dataclass(frozen=True)
class Miss:
    """A run over its limit under the new preset, with what its own files say about why: the
    training cost the multiplier held (``train/cost`` over the last 20% of epochs) and, for a
    run that picked its policy (``eval.delivery_epochs``), what the pick saw."""

    task: str
    algo: str
    seed: int
    cost: float  # the reported (protocol's) mean cost
    cost_limit: float
    training_cost: float
    pick_cost: float | None = None  # the pick's cost on its picking episodes
    candidates_within: int | None = None  # kept policies within the pick's limit
    candidates: int | None = None
    # The reported episodes' mean length and the task's time limit (None: not a registered
    # task): a policy whose episodes end before it, e.g. a walker that falls, pays its cost in
    # bursts that the training cost (a mean over whole training episodes) does not show.
    length: float = math.nan
    max_length: int | None = None

    @property
    def ends_early(self) -> bool:
        return self.max_length is not None and self.length < self.max_length

    @property
    def cause(self) -> str:
        """The run's key of MISS_CAUSES."""
        if self.candidates is not None:
            return "pick_reported_over" if self.candidates_within else "pick_none_within"
        return "training_over" if self.training_cost > self.cost_limit else "training_within"

    @property
    def reason(self) -> str:
        held = f"training cost {self.training_cost:.1f} over the last 20% of epochs"
        cause = self.cause
        if cause == "pick_none_within":
            reason = (f"none of the {self.candidates} kept policies was within the limit on its "
                      f"picking episodes (the cheapest: {self.pick_cost:.1f}); {held}")
        elif cause == "pick_reported_over":
            reason = (f"picked at {self.pick_cost:.1f} on its picking episodes "
                      f"({self.candidates_within} of {self.candidates} within), {self.cost:.1f} "
                      f"on the reported ones; {held}")
        else:
            reason = held
        if self.ends_early:
            reason += (f"; its episodes end early ({self.length:.0f} of {self.max_length} steps "
                       "on average)")
        return reason


def _miss(run: Run, evaluation: dict, protocol: str) -> Miss:
    training_cost = run.late_mean("train/cost")
    picked = {}
    record = run.final.get("delivered")
    if protocol == "delivered" and record is not None and evaluation is record:
        candidates = record.get("candidates", [])
        pick = picked_candidate(record)
        picked = {"pick_cost": pick["cost"] if pick else math.nan, "candidates": len(candidates),
                  "candidates_within": sum(c["cost"] <= record["pick_cost_limit"]
                                           for c in candidates)}
    spec = TASKS.get(run.task)
    return Miss(run.task, run.algo, run.seed, float(evaluation["cost_mean"]), run.cost_limit,
                training_cost, **picked, length=float(evaluation.get("length_mean", math.nan)),
                max_length=spec.max_episode_steps if spec else None)


@dataclass(frozen=True)
class Stop:
    """A run that gave up the task it had learned: its final evaluation's reward is at most
    ``moving_share`` of the best evaluation reward it logged in training (``eval/reward`` in
    ``metrics.csv``), e.g. SafetyPointGoal1's runs that reached goals by 100k frames and stood
    still from 600k. A run whose evaluations never earned a positive reward learned nothing to
    give up, and is not one."""

    side: str  # "before" or "after"
    task: str
    algo: str
    seed: int
    reward: float  # the protocol's final evaluation
    best_reward: float  # the best evaluation reward in training
    best_frames: int  # when it was logged


def _stop(run: Run, evaluation: dict, side: str, share: float) -> Stop | None:
    logged = list(zip(*run.column("eval/reward")))
    if not logged:
        return None
    best_frames, best_reward = max(logged, key=lambda point: point[1])
    reward = float(evaluation["reward_mean"])
    if best_reward <= 0 or reward > share * best_reward:
        return None
    return Stop(side, run.task, run.algo, run.seed, reward, float(best_reward), int(best_frames))


@dataclass(frozen=True)
class Target:
    """One question about the new preset, with the numbers that answer it; ``kind`` says which
    of TARGET_KINDS it is, for ``algo`` (and ``task`` where it is one task's); ``least`` is the
    least value that meets it (a count of runs for ``within``, a share of the old reward for
    ``reward_kept``), None where the target is 'all' or a pair of bounds."""

    name: str
    value: str
    met: bool
    kind: str = ""
    algo: str = ""
    task: str = ""
    least: float | None = None


#: The kinds of :class:`Target`, in the order ``before_after`` lists them.
TARGET_KINDS = {
    "within": "runs within the limit",
    "moving": "runs still moving (none stopped to buy its cost)",
    "reward_kept": "reward kept where the old preset kept its limit",
    "task": "one task's mean reward and cost",
}


@dataclass
class BeforeAfter:
    protocol: str
    rows: list[TaskRow]
    targets: list[Target]
    # (task, algo, seed, why): 'before only' / 'after only' (no run on the other side),
    # 'unfinished' (a side's run has no evaluation for the protocol)
    unpaired: list[tuple[str, str, int, str]]
    misses: list[Miss] = field(default_factory=list)  # paired runs over the limit after
    stops: list[Stop] = field(default_factory=list)  # paired runs that gave up their task

    def within(self, algo: str, side: str) -> tuple[int, int]:
        rows = [r for r in self.rows if r.algo == algo]
        return sum(r.within(side) for r in rows), sum(len(r.pairs) for r in rows)

    @property
    def algos(self) -> list[str]:
        return sorted({r.algo for r in self.rows})


def before_after(
    before: Sequence[str | Path],
    after: Sequence[str | Path],
    protocol: str = "last",
    *,
    within_target: Mapping[str, int] | None = None,
    reward_kept: float = 0.85,
    task_targets: Mapping[str, tuple[float, float]] | None = None,
    moving_share: float = 0.1,
) -> BeforeAfter:
    """Pair the runs of ``before`` and ``after`` (result trees) by task, algo and seed.

    Args:
        protocol: ``last`` (the policy at the end of training), ``best_feasible`` or ``delivered``
            (eval.delivery_epochs' pick; a run without the pick delivered its last policy).
        within_target: per algo, the runs (of those paired) that must be within the limit
            under the new preset; default: all of them.
        reward_kept: the share of the old mean reward the new preset must keep on every task
            and algo whose old mean cost was within the limit.
        task_targets: task -> (least mean reward, most mean cost) the new preset must reach,
            for each algo.
        moving_share: a run whose final reward is at most this share of the best evaluation
            reward it logged in training has stopped (:class:`Stop`); no run may after.
    """
    if protocol not in PROTOCOLS:
        raise ReportError(f"Unknown protocol {protocol!r}; valid: {', '.join(PROTOCOLS)}.")
    old, new = runs_by_key(before), runs_by_key(after)
    paired: dict[tuple[str, str], list[SeedPair]] = {}
    limits: dict[tuple[str, str], float] = {}
    unpaired, misses, stops = [], [], []
    for key in sorted(set(old) | set(new)):
        a = final_evaluation(old[key], protocol) if key in old else None
        b = final_evaluation(new[key], protocol) if key in new else None
        if a is None or b is None:
            why = ("after only" if key not in old else "before only" if key not in new
                   else "unfinished")
            unpaired.append((*key, why))
            continue
        if old[key].cost_limit != new[key].cost_limit:
            raise ReportError(
                f"{key[0]} {key[1]} seed {key[2]}: the cost limit is {old[key].cost_limit} "
                f"before and {new[key].cost_limit} after; a comparison needs one limit."
            )
        paired.setdefault(key[:2], []).append(
            SeedPair(key[2], float(a["reward_mean"]), float(a["cost_mean"]),
                     float(b["reward_mean"]), float(b["cost_mean"]),
                     old[key].late_mean("train/reward"), new[key].late_mean("train/reward"))
        )
        limits[key[:2]] = new[key].cost_limit
        if float(b["cost_mean"]) > new[key].cost_limit:
            misses.append(_miss(new[key], b, protocol))
        for side, run, evaluation in (("before", old[key], a), ("after", new[key], b)):
            stop = _stop(run, evaluation, side, moving_share)
            if stop is not None:
                stops.append(stop)
    if not paired:
        raise ReportError(
            "No task, algo and seed has a finished run on both sides: nothing to compare."
        )
    rows = [TaskRow(task, algo, limits[task, algo], pairs)
            for (task, algo), pairs in sorted(paired.items())]
    result = BeforeAfter(protocol, rows, [], unpaired, misses, stops)

    for algo in result.algos:
        within, total = result.within(algo, "after")
        before_within, _ = result.within(algo, "before")
        need = total if within_target is None else within_target.get(algo, total)
        result.targets.append(Target(
            f"{algo}: runs within the limit (after; before {before_within} of {total})",
            f"{within} of {total} (target >= {need})", within >= need, "within", algo,
            least=need))
    for algo in result.algos:
        _, total = result.within(algo, "after")
        stopped = {side: sum(s.algo == algo and s.side == side for s in stops)
                   for side in ("before", "after")}
        result.targets.append(Target(
            f"{algo}: runs still moving, reward above {moving_share:g} of their best in training "
            f"(after; before {total - stopped['before']} of {total})",
            f"{total - stopped['after']} of {total} (target: all)", not stopped["after"],
            "moving", algo))
    for row in rows:
        if row.mean("before_cost") <= row.cost_limit:
            kept = row.reward_kept
            value = f"{kept:.2f} of {row.mean('before_reward'):.1f} (target >= {reward_kept:.2f})"
            # Beside it, the share of the training reward: close to the evaluation's, the reward
            # was lost in training; well above it, at the final evaluation alone.
            training = row.kept("training_reward")
            if not math.isnan(training):
                value += (f"; training reward {training:.2f} of "
                          f"{row.mean('before_training_reward'):.1f}")
            result.targets.append(Target(
                f"{row.algo} {row.task}: reward kept (the old mean cost was within the limit)",
                value, bool(kept >= reward_kept), "reward_kept", row.algo, row.task, reward_kept))
    for task, (least_reward, most_cost) in (task_targets or {}).items():
        for row in (r for r in rows if r.task == task):
            reward, cost = row.mean("after_reward"), row.mean("after_cost")
            result.targets.append(Target(
                f"{row.algo} {task}: mean reward and cost (after)",
                f"{reward:.2f} / {cost:.2f} (target reward >= {least_reward:g}, "
                f"cost <= {most_cost:g})",
                reward >= least_reward and cost <= most_cost, "task", row.algo, task))
    return result


def _cell(test: TestResult) -> str:
    if math.isnan(test.pvalue):
        return f"{test.difference:+.2f} (—)"
    return f"{test.difference:+.2f} (p {test.pvalue:.2f})"


def write_markdown(result: BeforeAfter, path: str | Path, command: str = "") -> Path:
    """The comparison as a markdown page: the targets, then one row per task and algo."""
    lines = [f"# Before / after: {PROTOCOLS[result.protocol]}", ""]
    if command:
        lines += [f"Written by `{command}`.", ""]
    if result.protocol == "delivered":
        lines += ["A run without `eval.delivery_epochs` picked nothing: it is read as it was "
                  "delivered, by its last policy.", ""]
    lines += ["| target | value | met |", "|---|---|---|"]
    lines += [f"| {t.name} | {t.value} | {'yes' if t.met else 'no'} |" for t in result.targets]
    lines += [
        "",
        "Per task and algo, the mean over the seeds both presets ran (reward / cost), the runs "
        "within the limit, and the paired difference after - before with its t-test's p-value:",
        "",
        "| task | algo | seeds | before | after | within before | within after "
        "| reward diff | cost diff |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result.rows:
        n = len(row.pairs)
        lines.append(
            f"| {row.task} | {row.algo} | {','.join(str(p.seed) for p in row.pairs)} "
            f"| {row.mean('before_reward'):.1f} / {row.mean('before_cost'):.1f} "
            f"| {row.mean('after_reward'):.1f} / {row.mean('after_cost'):.1f} "
            f"| {row.within('before')}/{n} | {row.within('after')}/{n} "
            f"| {_cell(row.reward_test)} | {_cell(row.cost_test)} |"
        )
    if result.misses:
        lines += ["", "Runs over the limit after, and what their files say:", "",
                  "| task | algo | seed | cost (limit) | what the run shows |", "|---|---|---|---|---|"]
        lines += [f"| {m.task} | {m.algo} | {m.seed} | {m.cost:.1f} ({m.cost_limit:g}) | {m.reason} |"
                  for m in result.misses]
    if result.stops:
        lines += ["", "Runs that stopped (their final reward against the best evaluation reward "
                  "they logged in training):", "",
                  "| preset | task | algo | seed | final reward | best in training (frames) |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {s.side} | {s.task} | {s.algo} | {s.seed} | {s.reward:.1f} "
                  f"| {s.best_reward:.1f} ({s.best_frames}) |" for s in result.stops]
    if result.unpaired:
        lines += ["", f"Not paired ({len(result.unpaired)} runs), by task and algo with their seeds:",
                  ""]
        for why in ("before only", "after only", "unfinished"):
            seeds: dict[tuple[str, str], list[str]] = {}
            for task, algo, seed, reason in result.unpaired:
                if reason == why:
                    seeds.setdefault((task, algo), []).append(str(seed))
            if seeds:
                lines.append(f"- {why}: " + "; ".join(
                    f"{task} {algo} {', '.join(s)}" for (task, algo), s in seeds.items()) + ".")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path
