"""One algo against another on the same tasks under several presets: how the gap moves.

``s3rl-report gap --setting paper=results/reproduction --setting safe=results/table1_v2`` reads
each named setting's result trees and, on the tasks of the first setting (the one asked
about), puts the reference algo's final evaluation beside the baseline's under every setting:
the mean cost and reward of each, their difference (reference - baseline) with a paired t-test
over the seeds both ran, and the paper's Table 1 difference beside. Then one answer per setting
over the first setting's tasks it has both algos of (the same tasks once every setting is
complete; a task the first setting has one algo of is in none): rliable's
probability that a run of the reference has the lower cost (and the higher reward) than a run of
the baseline, with its stratified-bootstrap interval
(:func:`s3rl_torchrl.report.aggregate.probability_of_improvement`).

This is the question of issue 63: the paper's largest cost gaps come with a baseline whose
critics are unsound (``experiment=paper``); whether the gap stays when both algos read sound
critics (``experiment=safe``) says how much of it the baseline's critics made. A preset differs
from another in more than its critics (``configs/experiment/*.yaml``): the page names the
settings, not the cause.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.aggregate import Estimate, probability_of_improvement
from s3rl_torchrl.report.paper import paper_results_for
from s3rl_torchrl.report.runs import PROTOCOLS, ReportError, final_evaluation, runs_by_key
from s3rl_torchrl.report.stats import TestResult, paired_seed_test

__all__ = ["Gap", "SettingAnswer", "TaskGap", "format_difference", "gap", "write_markdown"]


@dataclass
class TaskGap:
    """One task under one setting: each algo's final evaluations by seed (mean over episodes)."""

    task: str
    setting: str
    cost_limit: float
    # algo -> seed -> (reward, cost)
    seeds: dict[str, dict[int, tuple[float, float]]]
    reference: str
    baseline: str
    reward_test: TestResult = field(init=False)
    cost_test: TestResult = field(init=False)

    def __post_init__(self) -> None:
        def column(algo: str, i: int) -> dict[int, float]:
            return {s: v[i] for s, v in self.seeds.get(algo, {}).items()}

        self.reward_test = paired_seed_test(column(self.reference, 0), column(self.baseline, 0))
        self.cost_test = paired_seed_test(column(self.reference, 1), column(self.baseline, 1))

    def mean(self, algo: str, metric: str) -> float:
        values = [v[0 if metric == "reward" else 1] for v in self.seeds.get(algo, {}).values()]
        return float(np.mean(values)) if values else math.nan

    def values(self, algo: str, metric: str) -> np.ndarray:
        i = 0 if metric == "reward" else 1
        return np.array([v[i] for _, v in sorted(self.seeds.get(algo, {}).items())])

    @property
    def complete(self) -> bool:
        """Both algos have at least one finished run."""
        return all(self.seeds.get(a) for a in (self.reference, self.baseline))


@dataclass(frozen=True)
class SettingAnswer:
    """One setting's aggregate over the tasks (of the first setting's) it has both algos of."""

    setting: str
    tasks: list[str]
    runs: tuple[int, int]  # (reference runs, baseline runs)
    lower_cost: Estimate  # P(a reference run's cost < a baseline run's)
    higher_reward: Estimate


@dataclass
class Gap:
    reference: str
    baseline: str
    protocol: str
    settings: dict[str, list[str]]  # name -> its result trees
    tasks: list[str]  # the first setting's tasks
    rows: dict[tuple[str, str], TaskGap]  # (task, setting) -> its runs (absent: none)
    shared: list[str]  # tasks every setting has both algos of
    answers: list[SettingAnswer]  # per setting with any such task
    missing: list[str] = field(default_factory=list)  # "<setting>: <task> <algo>" lines

    def paper_difference(self, task: str, metric: str) -> float:
        """The paper's Table 1 (Lagrangian rows) reference - baseline difference, NaN when the
        paper has no such pair."""
        found = {v.algo: v.mean for v in paper_results_for(task)
                 if v.table == "Table 1" and v.setting == "Lag" and v.metric == metric}
        a, b = self.reference, self.baseline
        return found[a] - found[b] if a in found and b in found else math.nan


def gap(
    settings: Mapping[str, Sequence[str | Path]],
    reference: str = "s3rl",
    baseline: str = "sac_lag",
    protocol: str = "last",
    *,
    reps: int = 2000,
    seed: int = 0,
) -> Gap:
    """Read every setting's result trees (name -> trees, the first the one asked about).

    Args:
        protocol: ``last``, ``best_feasible`` or ``delivered`` (a run without the pick delivered
            its last policy: :func:`s3rl_torchrl.report.runs.final_evaluation`).
        reps, seed: the bootstrap's resamples and seed.
    """
    if protocol not in PROTOCOLS:
        raise ReportError(f"Unknown protocol {protocol!r}; valid: {', '.join(PROTOCOLS)}.")
    if len(settings) < 1:
        raise ReportError("Name at least one setting (NAME=DIR[,DIR...]).")
    if reference == baseline:
        raise ReportError(f"The reference and the baseline are both {reference!r}.")
    read = {name: runs_by_key(trees) for name, trees in settings.items()}
    first = next(iter(read))
    tasks = sorted({task for task, algo, _ in read[first] if algo in (reference, baseline)})
    if not tasks:
        raise ReportError(f"Setting {first!r} has no run of {reference} or {baseline} in "
                          f"{', '.join(map(str, settings[first]))}.")
    rows: dict[tuple[str, str], TaskGap] = {}
    for name, runs in read.items():
        # task -> algo -> seed -> (reward, cost), and task -> the limits its runs trained for
        seeds: dict[str, dict[str, dict[int, tuple[float, float]]]] = {}
        limits: dict[str, set[float]] = {}
        for (task, algo, s), run in runs.items():
            if task not in tasks or algo not in (reference, baseline):
                continue
            evaluation = final_evaluation(run, protocol)
            if evaluation is None:
                continue
            seeds.setdefault(task, {}).setdefault(algo, {})[s] = (
                float(evaluation["reward_mean"]), float(evaluation["cost_mean"]))
            limits.setdefault(task, set()).add(run.cost_limit)
        for task, by_algo in seeds.items():
            if len(limits[task]) > 1:
                raise ReportError(f"{name}: {task}'s runs trained for different cost limits "
                                  f"({', '.join(f'{c:g}' for c in sorted(limits[task]))}).")
            rows[task, name] = TaskGap(task, name, limits[task].pop(), by_algo, reference,
                                       baseline)
    missing = [f"{name}: {task} {algo}" for name in read for task in tasks
               for algo in (reference, baseline)
               if not rows.get((task, name)) or not rows[task, name].seeds.get(algo)]
    shared = [t for t in tasks if all((t, n) in rows and rows[t, n].complete for n in read)]
    # The first setting's question is asked on the tasks it has both algos of; another setting
    # answers on those of them it has both algos of too, never on a task the question has not
    # reached (one whose first setting has runs of a single algo so far).
    asked = [t for t in tasks if (t, first) in rows and rows[t, first].complete]
    answers = []
    for name in read:
        # The same tasks for every setting once all are in (``shared``); the page says which
        # tasks each answer is over.
        own = [t for t in asked if (t, name) in rows and rows[t, name].complete]
        if not own:
            continue
        by_metric = {}
        for metric in ("cost", "reward"):
            ref = {t: rows[t, name].values(reference, metric) for t in own}
            base = {t: rows[t, name].values(baseline, metric) for t in own}
            by_metric[metric], _ = probability_of_improvement(
                ref, base, lower_is_better=metric == "cost", reps=reps, seed=seed)
        runs = tuple(sum(len(rows[t, name].seeds[a]) for t in own) for a in (reference, baseline))
        answers.append(SettingAnswer(name, own, runs, by_metric["cost"], by_metric["reward"]))
    return Gap(reference, baseline, protocol, {n: [str(t) for t in v] for n, v in
                                               settings.items()},
               tasks, rows, shared, answers, missing)


def format_difference(test: TestResult) -> str:
    """A paired test's cell: the difference, its 95% interval and p; where the test is undefined
    (one pair, or no difference on any pair) the pairs and why instead. The same non-zero
    difference on every pair keeps scipy's p of 0, flagged."""
    if math.isnan(test.difference):
        return "–"
    if math.isnan(test.pvalue):
        return f"{test.difference:+.2f} ({test.n}{'; ' + test.note if test.note else ''})"
    return (f"{test.difference:+.2f} [{test.ci_low:+.2f}, {test.ci_high:+.2f}], "
            f"p {test.pvalue:.2f}" + (f" ({test.note})" if test.note else ""))


def _mean(row: TaskGap | None, algo: str, metric: str) -> str:
    if row is None or not row.seeds.get(algo):
        return "–"
    return f"{row.mean(algo, metric):.2f} ({len(row.seeds[algo])})"


def write_markdown(result: Gap, path: str | Path, command: str = "") -> Path:
    """The page: per task and setting the two algos and their difference, then the answers."""
    ref, base = result.reference, result.baseline
    lines = [f"# {ref} against {base} under {len(result.settings)} settings: "
             f"{PROTOCOLS[result.protocol]}", ""]
    if command:
        lines += [f"Written by `{command}`.", ""]
    lines += ["Settings (each a preset's result trees):", ""]
    lines += [f"- **{name}**: {', '.join(f'`{t}`' for t in trees)}"
              for name, trees in result.settings.items()]
    if result.protocol == "delivered":
        lines += ["", "A run without `eval.delivery_epochs` picked nothing: it is read by its "
                  "last policy."]
    for metric in ("cost", "reward"):
        lines += [
            "", f"## {metric.capitalize()}", "",
            f"Per task, the mean final {metric} over each algo's finished seeds (their number in "
            f"brackets) and the difference {ref} − {base} over the seeds both ran, with its 95% "
            f"interval and paired t-test; the paper's difference from its Table 1 beside.", "",
            f"| task | setting | {ref} | {base} | {ref} − {base} | paper's difference |",
            "|---|---|---:|---:|---|---:|",
        ]
        for task in result.tasks:
            paper = result.paper_difference(task, metric)
            for i, name in enumerate(result.settings):
                row = result.rows.get((task, name))
                test = getattr(row, f"{metric}_test") if row is not None else None
                lines.append(
                    f"| {task if i == 0 else ''} | {name} | {_mean(row, ref, metric)} "
                    f"| {_mean(row, base, metric)} | {format_difference(test) if test else '–'} "
                    f"| {'' if i else ('–' if math.isnan(paper) else f'{paper:+.2f}')} |")
    lines += ["", "## Over the tasks", ""]
    if result.answers:
        lines += [
            f"Per setting, over the tasks it and the first setting have finished runs of both "
            f"algos of: the probability "
            f"that a run of {ref} has the lower cost (the higher reward) than a run of {base} of "
            "the same task, averaged over the tasks (rliable), with its 95% stratified-bootstrap "
            "interval; 0.5: no difference. Settings are comparable where their tasks are the "
            "same" + (f" (all: {', '.join(result.shared)})." if result.shared else
                      "; no task is in every setting yet."), "",
            f"| setting | tasks | runs ({ref} / {base}) | P(lower cost) | P(higher reward) |",
            "|---|---|---:|---:|---:|",
        ]
        lines += [f"| {a.setting} | {len(a.tasks)}: {', '.join(a.tasks)} "
                  f"| {a.runs[0]} / {a.runs[1]} "
                  f"| {a.lower_cost.cell()} | {a.higher_reward.cell()} |" for a in result.answers]
    else:
        lines.append("No setting has finished runs of both algos on any task yet.")
    if result.missing:
        by_setting: dict[str, list[str]] = {}
        for line in result.missing:
            name, _, what = line.partition(": ")
            by_setting.setdefault(name, []).append(what)
        lines += ["", "Without a finished run: " + "; ".join(
            f"{name}: {', '.join(what)}" for name, what in by_setting.items()) + "."]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path
