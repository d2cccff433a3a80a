"""How long SafetyPointGoal1's runs held issue 60's goal target while they trained: per run, the
windows of 3 consecutive epochs (3 x 2 evaluation episodes) past lambda's warm-up whose mean
evaluation reward is >= 20 at a mean evaluation cost <= the limit, and the most reward of a
window within the limit (research/2026-12-07-pointgoal1-horizon.md, "What ten settings say").
With ``--spans``, the means over spans of frames instead (the note's 3M tables); with ``--held``,
how long each run held the goal while lambda was on and at what training cost (the note's "goal
held until" and "training cost while held" columns, as in the critic selection's round 4):

    python research/delivered_policy/goal_windows.py research/results/delivered_selection \
        results/table1_v2
    python research/delivered_policy/goal_windows.py research/results/goal_3m \
        --spans 0.8-1,1-1.5,1.5-2,2-2.5,2.5-3
    python research/delivered_policy/goal_windows.py research/results/delivered_selection --held
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.runs import find_runs

sys.path.insert(0, str(Path(__file__).resolve().parent))  # research/ is not a package
from summarise import markdown  # noqa: E402

TASK = "SafetyPointGoal1-v0"
REWARD_TARGET = 20.0  # the issue's: mean reward >= 20 at mean cost <= 25
WIDTH = 3
START_FRAMES = 100_000  # SAFE_TASK_SETTINGS' warm-up: lambda is 0 before it


def target_windows(
    frames, reward, cost, limit: float, *, reward_target: float = REWARD_TARGET,
    width: int = WIDTH, start: int = START_FRAMES,
) -> tuple[int, int, float, int | None]:
    """(windows, windows on target, the most reward of a window within the limit, the last frame
    of that window) over the epochs after ``start`` frames; a window is ``width`` consecutive
    epochs, its reward and cost their means."""
    frames, reward, cost = (np.asarray(a, dtype=float) for a in (frames, reward, cost))
    keep = frames > start
    frames, reward, cost = frames[keep], reward[keep], cost[keep]
    if frames.size < width:
        return 0, 0, float("nan"), None
    kernel = np.ones(width) / width
    mean_reward = np.convolve(reward, kernel, mode="valid")
    mean_cost = np.convolve(cost, kernel, mode="valid")
    within = mean_cost <= limit
    hits = int(np.sum(within & (mean_reward >= reward_target)))
    if not within.any():
        return mean_reward.size, hits, float("nan"), None
    best = int(np.argmax(np.where(within, mean_reward, -np.inf)))
    return mean_reward.size, hits, float(mean_reward[best]), int(frames[best + width - 1])


def goal_runs(roots: list[Path]):
    """``(root, run)`` for every SafetyPointGoal1 run exported under each of ``roots``."""
    for root in roots:
        for run in find_runs(root):
            if run.task == TASK:
                yield root, run


def rows(roots: list[Path]) -> list[list[str]]:
    table = []
    for root, run in goal_runs(roots):
        frames, reward = run.column("eval/reward")
        _, cost = run.column("eval/cost")
        windows, hits, best, at = target_windows(frames, reward, cost, run.cost_limit)
        table.append([
            str(run.path.relative_to(root.parent)), f"{run.frames // 1000}k", str(windows),
            str(hits), "–" if at is None else f"{best:.1f} ({at // 1000}k)",
        ])
    return table


# (header, metrics.csv columns, decimals): a span's means, "a / b" where a cell has two columns.
SPAN_CELLS = [
    ("eval reward / cost", ("eval/reward", "eval/cost"), 1),
    ("training reward / cost", ("train/reward", "train/cost"), 1),
    ("lambda", ("lagrangian",), 2),
    ("reward critic / return", ("critic/reward_q", "critic/reward_return"), 2),
    ("cost critic / return", ("critic/cost_q", "critic/cost_return"), 2),
]


def span_means(frames, values, low: float, high: float) -> float | None:
    """The mean of ``values`` over the epochs with ``low < frames <= high``; None unless the run
    reached ``high``."""
    frames, values = np.asarray(frames, dtype=float), np.asarray(values, dtype=float)
    if frames.size == 0 or frames.max() < high:
        return None
    return float(values[(frames > low) & (frames <= high)].mean())


def span_rows(roots: list[Path], spans: list[tuple[float, float]]) -> list[list[str]]:
    table = []
    for root, run in goal_runs(roots):
        series = {column: run.column(column)
                  for _, columns, _ in SPAN_CELLS for column in columns}
        for low, high in spans:
            cells = []
            for _, columns, digits in SPAN_CELLS:
                means = [span_means(*series[column], low, high) for column in columns]
                if None in means:
                    break
                cells.append(" / ".join(f"{mean:.{digits}f}" for mean in means))
            else:
                table.append([str(run.path.relative_to(root.parent)),
                              f"{low / 1e6:g}-{high / 1e6:g}M", *cells])
    return table


HELD_REWARD = 15.0  # a 3-epoch mean evaluation reward the note counts as still reaching goals


def goal_held(
    frames, lagrangian, eval_reward, train_reward, train_cost, *, held_reward: float = HELD_REWARD,
    reward_target: float = REWARD_TARGET, width: int = WIDTH,
) -> tuple[int, float, float, float] | None:
    """(the last frame with lambda > 0 whose trailing ``width``-epoch mean evaluation reward is
    >= ``held_reward``, lambda there, the mean training cost over the epochs with lambda > 0 up
    to it, the lowest training cost of those epochs whose training reward is >= ``reward_target``
    (nan if none)); None if the goal was never held while lambda was on."""
    frames, lam, eval_reward, train_reward, train_cost = (
        np.asarray(a, dtype=float)
        for a in (frames, lagrangian, eval_reward, train_reward, train_cost)
    )
    if frames.size < width:
        return None
    trailing = np.full(frames.size, np.nan)
    trailing[width - 1:] = np.convolve(eval_reward, np.ones(width) / width, mode="valid")
    held = np.flatnonzero((lam > 0) & (trailing >= held_reward))
    if held.size == 0:
        return None
    last = int(held[-1])
    on = (lam > 0) & (np.arange(frames.size) <= last)
    rewarded = on & (train_reward >= reward_target)
    lowest = float(train_cost[rewarded].min()) if rewarded.any() else float("nan")
    return int(frames[last]), float(lam[last]), float(train_cost[on].mean()), lowest


def held_rows(roots: list[Path]) -> list[list[str]]:
    table = []
    for root, run in goal_runs(roots):
        frames, lam = run.column("lagrangian")
        series = [run.column(column)[1] for column in ("eval/reward", "train/reward",
                                                       "train/cost")]
        held = goal_held(frames, lam, *series)
        cells = ["–", "–"] if held is None else [
            f"{held[0] // 1000}k ({held[1]:.2f})", f"{held[2]:.1f} ({held[3]:.1f})"]
        table.append([str(run.path.relative_to(root.parent)), f"{run.frames // 1000}k", *cells])
    return table


def parse_spans(text: str) -> list[tuple[float, float]]:
    """``"0.8-1,1-1.5"`` (millions of frames) -> ``[(800000.0, 1000000.0), (1e6, 1.5e6)]``."""
    spans = []
    for span in text.split(","):
        low, _, high = span.partition("-")
        try:
            spans.append((float(low) * 1e6, float(high) * 1e6))
        except ValueError:
            raise SystemExit(f"--spans: {span!r} is not <low>-<high> in millions of frames, "
                             "e.g. 0.8-1,1-1.5") from None
    return spans


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="+", type=Path, help="directories of exported runs")
    parser.add_argument("--spans", default=None,
                        help="means over these spans of frames instead, in millions: 0.8-1,1-1.5")
    parser.add_argument("--held", action="store_true",
                        help="how long each run held the goal while lambda was on instead")
    args = parser.parse_args()
    if args.held:
        header = ["run", "frames", f"goal held until (lambda): last 3-epoch mean eval reward >= "
                  f"{HELD_REWARD:g}", "training cost while held (lowest epoch with training "
                  f"reward >= {REWARD_TARGET:g})"]
        print("\n".join(markdown(header, held_rows(args.roots))))
        return
    if args.spans is not None:
        header = ["run", "frames", *(name for name, _, _ in SPAN_CELLS)]
        print("\n".join(markdown(header, span_rows(args.roots, parse_spans(args.spans)))))
        return
    header = ["run", "frames", "3-epoch windows", f"reward >= {REWARD_TARGET:g} at cost <= limit",
              "most reward within the limit (window's last frame)"]
    print("\n".join(markdown(header, rows(args.roots))))


if __name__ == "__main__":
    main()
