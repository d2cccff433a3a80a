"""The selection table of the delivered-policy controller: one row per run of
`selection.py`, read from its exported files (config.json, metrics.csv, final_eval.json).

    python research/delivered_policy/summarise.py research/results/delivered_selection \
        --out research/delivered_policy/selection.md

Per run: the candidate (the directory below the root), the last policy's and the delivered
pick's final evaluation (reward / cost, 10 episodes; the pick's cost on the 5 episodes it was
picked on beside), the training cost and the share of epochs
whose 2-episode evaluation was over the limit, both over the last 20% of the run's frames, and
lambda's mean there. Unfinished runs are listed with the frames they reached. Then how far
the picks' reported costs land from their picking costs (:func:`pick_optimism`).

Then one row per candidate and protocol (the last policy; the delivered pick), over its finished
runs: how many keep the limit, and their reward against the committed runs of the same algo and
task (the mean last-policy reward of seeds 10/20/30 in results/safe_sound + results/table1),
as the median of the ratios. research/2026-11-28-delivered-policy.md states the rule that
chooses from this table; the last line applies it (:func:`choice`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.runs import find_runs, picked_candidate

ROOT = Path(__file__).resolve().parents[2]
# The committed runs under experiment=safe: what the issue counts against.
COMMITTED = (ROOT / "results" / "safe_sound", ROOT / "results" / "table1")


def tail(run, column: str, share: float = 0.2) -> np.ndarray:
    frames, values = run.column(column)
    start = (1 - share) * run.total_frames
    return np.array([v for f, v in zip(frames, values) if f > start], dtype=float)


def rows(root: Path) -> list[list[str]]:
    table = []
    for run in find_runs(root):
        candidate = run.path.relative_to(root).parts[0]
        limit = run.cost_limit
        train_cost = tail(run, "train/cost")
        eval_cost = tail(run, "eval/cost")
        lam = tail(run, "lagrangian")
        if run.finished:
            last = f"{run.final['reward_mean']:.1f} / {run.final['cost_mean']:.1f}"
            picked = run.final.get("delivered")
            delivered = "–" if picked is None else (
                f"{picked['reward_mean']:.1f} / {picked['cost_mean']:.1f} (epoch {picked['epoch']}; "
                f"{picking_cost(picked):.1f} on its picking episodes)"
            )
        else:
            last = delivered = f"running ({run.frames // 1000}k of {run.total_frames // 1000}k)"
        table.append([
            candidate, run.algo, run.task, str(run.seed), f"{limit:g}", last, delivered,
            f"{np.nanmean(train_cost):.1f}" if train_cost.size else "–",
            f"{np.mean(eval_cost > limit):.2f}" if eval_cost.size else "–",
            f"{np.nanmean(lam):.3f}" if lam.size else "–",
        ])
    return sorted(table, key=lambda r: (r[2], r[1], int(r[3]), r[0]))


def picking_cost(picked: dict) -> float:
    """The pick's mean cost on the episodes it was picked on (its candidate's entry)."""
    return picked_candidate(picked)["cost"]


def pick_optimism(root: Path) -> str:
    """How far each pick's reported cost (10 fresh episodes) lands from the cost it was picked
    at (5 episodes): picking the most reward among candidates judged on few episodes favours one
    whose cost was read low by chance, and this is the size of it on these runs."""
    picks = [(run.final["delivered"], run.cost_limit) for run in find_runs(root)
             if run.finished and run.final.get("delivered")]
    gaps = [picked["cost_mean"] - picking_cost(picked) for picked, _ in picks]
    over = sum(picked["cost_mean"] > limit for picked, limit in picks)
    return (f"The picks' reported cost minus their cost on the picking episodes, over {len(picks)} "
            f"picks: median {np.median(gaps):+.1f}, mean {np.mean(gaps):+.1f}, largest "
            f"{max(gaps):+.1f}; {over} of them over the limit on the reported episodes.")


def committed_rewards(roots=COMMITTED) -> dict[tuple[str, str], float]:
    """(algo, task) -> the committed runs' mean last-policy reward."""
    rewards: dict[tuple[str, str], list[float]] = {}
    for root in roots:
        for run in find_runs(root):
            if run.finished:
                rewards.setdefault((run.algo, run.task), []).append(run.final["reward_mean"])
    return {key: float(np.mean(values)) for key, values in rewards.items()}


def candidate_tally(
    root: Path, committed: dict[tuple[str, str], float]
) -> dict[tuple[str, str], tuple[int, int, float | None]]:
    """(candidate, protocol) -> (finished runs within the limit, finished runs, the median of
    their reward over the committed group's mean reward; None where no group earns reward)."""
    results: dict[tuple[str, str], list[tuple[bool, float | None]]] = {}
    for run in find_runs(root):
        if not run.finished:
            continue
        candidate = run.path.relative_to(root).parts[0]
        reference = committed[(run.algo, run.task)]
        evaluated = {"last policy": run.final, "delivered pick": run.final.get("delivered")}
        for protocol, result in evaluated.items():
            if result is not None:
                # A ratio only against a group that earns reward (SafetyPointGoal1's committed
                # runs earn ~0: its target is absolute, reward >= 20).
                ratio = result["reward_mean"] / reference if reference > 1.0 else None
                results.setdefault((candidate, protocol), []).append(
                    (result["cost_mean"] <= run.cost_limit, ratio)
                )
    tally = {}
    for key, runs in sorted(results.items()):
        ratios = [r for _, r in runs if r is not None]
        median = float(np.median(ratios)) if ratios else None
        tally[key] = (sum(within for within, _ in runs), len(runs), median)
    return tally


def candidate_rows(tally: dict[tuple[str, str], tuple[int, int, float | None]]) -> list[list[str]]:
    """:func:`candidate_tally` as table rows."""
    return [
        [candidate, protocol, f"{kept} of {runs}", "–" if median is None else f"{median:.2f}"]
        for (candidate, protocol), (kept, runs, median) in tally.items()
    ]


CANDIDATE_HEADER = ["candidate", "protocol", "within the limit",
                    "reward / committed mean (median)"]

# The rule of research/2026-11-28-delivered-policy.md ("How the preset is chosen"), items 1-3:
# it chooses among these candidates (selection.py's CANDIDATES) once each has its 14 runs
# (selection.py's seven margin/aim groups x seeds 1 and 2).
RULE_CANDIDATES = ("margin", "aim")
RULE_RUNS = 14
RULE_REWARD_KEPT = 0.85
RULE_WITHIN = 13


def choice(tally: dict[tuple[str, str], tuple[int, int, float | None]]) -> str:
    """The rule applied to :func:`candidate_tally` (unrounded ratios): the candidate and
    protocol with the most runs within the limit, a tie going to the higher median reward ratio
    (1), passing over a median ratio below 0.85 (2), and whether it keeps fewer than 13 of 14
    (3)."""
    ranked, finished = [], {}
    for (candidate, protocol), (kept, runs, median) in tally.items():
        if candidate in RULE_CANDIDATES:
            finished[candidate] = runs
            ranked.append((kept, median, candidate, protocol))
    done = sum(finished.values())
    if len(finished) < len(RULE_CANDIDATES) or min(finished.values()) < RULE_RUNS:
        return (f"The rule decides once each of {', '.join(RULE_CANDIDATES)} has its {RULE_RUNS} "
                f"runs: {done} of {RULE_RUNS * len(RULE_CANDIDATES)} have finished.")
    ranked.sort(key=lambda r: (r[0], r[1]), reverse=True)
    passed = [r for r in ranked if r[1] < RULE_REWARD_KEPT]
    kept_reward = [r for r in ranked if r[1] >= RULE_REWARD_KEPT]
    lines = []
    for kept, median, candidate, protocol in passed:
        if not kept_reward or (kept, median) > kept_reward[0][:2]:
            lines.append(f"Passed over (reward ratio {median:.2f} < {RULE_REWARD_KEPT}): "
                         f"{candidate}, {protocol} ({kept} of {RULE_RUNS}).")
    if not kept_reward:
        return " ".join(lines + [f"No candidate keeps {RULE_REWARD_KEPT} of the reward: the rule "
                                 "chooses none."])
    kept, median, candidate, protocol = kept_reward[0]
    lines.append(f"The rule's choice: {candidate}, {protocol} ({kept} of {RULE_RUNS} within the "
                 f"limit, reward ratio {median:.2f}).")
    if kept < RULE_WITHIN:
        lines.append(f"Fewer than {RULE_WITHIN} of {RULE_RUNS}: the evidence runs with it and the "
                     "docs state the miss.")
    return " ".join(lines)


def markdown(header: list[str], table: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(row) + " |" for row in table
    ]


HEADER = ["candidate", "algo", "task", "seed", "limit", "last policy: reward / cost",
          "delivered pick: reward / cost", "train cost, last 20%",
          "epochs over the limit, last 20%", "lambda, last 20%"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = markdown(HEADER, rows(args.root)) + ["", pick_optimism(args.root)]
    tally = candidate_tally(args.root, committed_rewards())
    lines += ["", *markdown(CANDIDATE_HEADER, candidate_rows(tally)), "", choice(tally)]
    text = "\n".join(lines) + "\n"
    if args.out is None:
        print(text)
    else:
        args.out.write_text(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
