"""Issue 60: a task's own training-cost target, chosen on seeds 1 and 2 by the rule that
research/2026-12-08-antcircle-target.md states before any of its runs was read.

The preset holds every task's training cost at 0.7 of the limit (`algo.lagrangian_target`), the
margin its delivered policy needs where that policy costs more than the training episodes. On
SafetyAntCircle-v0 Table 1's deterministic policies cost less than its training episodes, and the
evidence's AntCircle runs kept less than 0.85 of Table 1's reward. The candidate trains it as
Table 1 did (target 1.0), everything else the preset's, with the preset's delivered pick:

    python research/delivered_policy/task_targets.py run --out /work/runs/task_targets \
        --export research/results/task_targets
    python research/delivered_policy/task_targets.py summarise research/results/task_targets \
        --out research/delivered_policy/task_targets.md

The queue is selection.py's (`run_queue`): resumable, each finished run copied to `--export`,
runs copied already skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from s3rl_torchrl.report.runs import find_runs

sys.path.insert(0, str(Path(__file__).resolve().parent))  # research/ is not a package
from selection import queued_run, run_or_summarise  # noqa: E402
from summarise import committed_rewards, markdown, tail  # noqa: E402

FRAMES = 1_000_000
SEEDS = [1, 2]  # the reported seeds are 10, 20 and 30
ALGOS = ["sac_lag", "s3rl"]
# candidate -> (task, overrides)
CANDIDATES = {
    "antcircle_target1": ("SafetyAntCircle-v0", ["algo.lagrangian_target=1.0"]),
}
REWARD_KEPT = 0.85  # issue 60's share of Table 1's reward


def jobs(out: Path):
    """Seed 1 of both algos, then seed 2."""
    for name, (task, overrides) in CANDIDATES.items():
        for seed in SEEDS:
            for algo in ALGOS:
                run_dir = out / name / f"{algo}_{task}" / f"seed{seed}"
                yield queued_run(run_dir, task, algo, seed, FRAMES, *overrides)


def summarise(root: Path) -> str:
    """Per run: the last policy, the delivered pick and the training episodes over the last
    fifth of frames; per candidate, the rule's verdict (`verdict`)."""
    reference = committed_rewards()
    lines: list[str] = []
    for name, (task, _) in CANDIDATES.items():
        found = find_runs(root / name) if (root / name).is_dir() else []
        runs = sorted((run for run in found if run.finished), key=lambda run: (run.algo, run.seed))
        table = []
        for run in runs:
            pick = run.final["delivered"]
            table.append([
                name, run.algo, str(run.seed),
                f"{run.final['reward_mean']:.1f} / {run.final['cost_mean']:.1f}",
                f"{pick['reward_mean']:.1f} / {pick['cost_mean']:.1f} (epoch {pick['epoch']})",
                f"{pick['reward_mean'] / reference[(run.algo, task)]:.2f}",
                f"{tail(run, 'train/reward').mean():.1f} / {tail(run, 'train/cost').mean():.1f}",
            ])
        lines += [f"{task}, {FRAMES // 1000}k frames, limit "
                  f"{runs[0].cost_limit:g}:" if runs else f"{task}:", ""]
        lines += markdown(
            ["candidate", "algo", "seed", "last policy", "delivered pick",
             "pick reward / Table 1's mean", "training reward / cost, last 20%"],
            table,
        )
        lines += ["", verdict(name, runs, reference)]
    return "\n".join(lines) + "\n"


def verdict(name: str, runs, reference: dict[tuple[str, str], float]) -> str:
    """The stated rule: the candidate enters the task's settings only if every pick of the
    round (both algos, seeds 1 and 2) is within the limit on its reported episodes and, per
    algo, the median of the picks' reward over Table 1's mean reward is at least 0.85."""
    expected = len(SEEDS) * len(ALGOS)
    over = [run for run in runs if run.final["delivered"]["cost_mean"] > run.cost_limit]
    if len(runs) < expected:
        # A part of the round decides nothing but a miss: a pick over the limit stays over it
        # whatever the other runs give.
        if over:
            return (f"The rule's verdict on {name}: it misses ({len(over)} of the {len(runs)} "
                    f"finished picks over the limit; every one of the {expected} must be within, "
                    f"so the other {expected - len(runs)} runs cannot change it).")
        return f"The rule's verdict on {name}: not yet ({len(runs)} of {expected} runs finished)."
    kept = {
        algo: float(np.median([run.final["delivered"]["reward_mean"] / reference[(algo, run.task)]
                               for run in runs if run.algo == algo]))
        for algo in ALGOS
    }
    short = [algo for algo in ALGOS if kept[algo] < REWARD_KEPT]
    shares = ", ".join(f"{algo} {kept[algo]:.2f}" for algo in ALGOS)
    if over or short:
        reasons = []
        if over:
            reasons.append(f"{len(over)} of {expected} picks over the limit")
        if short:
            reasons.append(f"reward kept below {REWARD_KEPT} for {', '.join(short)}")
        return f"The rule's verdict on {name}: it misses ({'; '.join(reasons)}; reward kept: {shares})."
    return (f"The rule's verdict on {name}: it enters ({expected} of {expected} picks within the "
            f"limit; reward kept: {shares}).")


def main() -> None:
    run_or_summarise(__doc__.splitlines()[0], jobs, summarise)


if __name__ == "__main__":
    main()
