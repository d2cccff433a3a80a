"""Which committed final evaluations counted a rollout's cut remainder as an episode.

Until 2026-12-01 ``episode_statistics`` (``s3rl_torchrl/trainer/evaluation.py``) closed every
env copy's last episode at the rollout's end: after a fall, the fresh episode that followed was
counted, cut at ``eval.max_steps`` total steps (it now takes each copy's first episode only). Each row of a rollout sums to
``max_steps``, so the stored ``episode_lengths`` show which entries were such remainders (the
last of a row that is not its first). For each result tree and policy this prints the runs
with one, the mean cost and reward as committed, and over the complete episodes among them
(fewer than ten, so an estimate of what whole episodes give, not a new evaluation).

    python research/evaluation_remainders.py [results/table1 results/table1_v2 ...]
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from s3rl_torchrl.envs.registry import get_task
from s3rl_torchrl.report.runs import find_runs

# The final_eval.json record of each policy (s3rl_torchrl.report.runs.PROTOCOLS), by its label.
POLICIES = {"last": None, "delivered pick": "delivered", "best-feasible": "best_feasible"}


def remainders(lengths: list[int], max_steps: int) -> list[bool]:
    """True for each episode that a rollout row's end cut after a reset inside the row."""
    flags, steps, first = [], 0, True
    for length in lengths:
        steps += length
        if steps >= max_steps:
            flags.append(not first)
            steps, first = 0, True
        else:
            flags.append(False)
            first = False
    return flags


def main(trees: list[str]) -> None:
    print(
        "| tree | policy | run | remainders | cost: committed / whole episodes | reward: committed / whole episodes |"
    )
    print("|---|---|---|---:|---|---|")
    for tree in trees:
        counts = {}
        for run in find_runs(tree):
            if run.final is None:
                continue
            max_steps = run.config["eval"].get("max_steps") or get_task(run.task).max_episode_steps
            for policy, key in POLICIES.items():
                # Not final_evaluation(): it stands a run without a pick's last policy in for
                # its pick, which would count that evaluation twice here.
                result = run.final if key is None else run.final.get(key)
                if not result or "episode_lengths" not in result:
                    continue
                flags = remainders(result["episode_lengths"], max_steps)
                total, hit = counts.get(policy, (0, 0))
                counts[policy] = (total + 1, hit + any(flags))
                if not any(flags):
                    continue
                whole = [i for i, flag in enumerate(flags) if not flag]
                cost = statistics.fmean(result["episode_costs"][i] for i in whole)
                reward = statistics.fmean(result["episode_rewards"][i] for i in whole)
                print(
                    f"| {Path(tree).name} | {policy} | {run.algo}_{run.task} seed {run.seed} | "
                    f"{sum(flags)} | {result['cost_mean']:.1f} / {cost:.1f} | "
                    f"{result['reward_mean']:.0f} / {reward:.0f} |"
                )
        for policy, (total, hit) in counts.items():
            print(
                f"| {Path(tree).name} | {policy} | runs with a remainder | {hit} of {total} | | |"
            )


if __name__ == "__main__":
    main(
        sys.argv[1:]
        or ["results/table1", "results/safe_sound", "results/table1_v2", "results/reproduction"]
    )
