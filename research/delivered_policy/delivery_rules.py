"""Issue 60's third round: which policy a run should deliver, read on runs that train as the
preset does (research/2026-12-04-delivery-rules.md states the rule before any run was read).

The evidence (results/table1_v2) missed because the deterministic policy of any one epoch is a
draw from a wide spread whose mean sits below the limit. This round trains the preset
(`experiment=safe`, unchanged: target 0.7, 10 kept epochs) on seeds 1 and 2 of the 15 groups
that missed in the evidence (SafetyPointGoal1 aside), at 1M frames, and records in each run what
the candidate delivery rules need:

- `eval.delivery_report_all=true`: every kept policy is also evaluated on 10 reporting episodes,
  so that a pick under a stricter share of the limit can be read off the same run;
- `eval.ema_horizons=[2000,10000]`: the actor's weight averages over ~1 and ~5 epochs (2000
  gradient steps an epoch), evaluated at every epoch and on the final episodes.

    python research/delivered_policy/delivery_rules.py run --out /work/runs/delivery_rules \
        --export research/results/delivery_rules [--workers 1]
    python research/delivered_policy/delivery_rules.py summarise research/results/delivery_rules \
        --out research/delivered_policy/delivery_rules.md

The queue is selection.py's (`run_queue`): resumable, each finished run copied to `--export`,
runs copied already skipped.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from s3rl_torchrl.report.runs import find_runs
from s3rl_torchrl.trainer.evaluation import pick_delivered

sys.path.insert(0, str(Path(__file__).resolve().parent))  # research/ is not a package
from selection import queued_run, run_or_summarise  # noqa: E402
from summarise import committed_rewards, tail  # noqa: E402

FRAMES = 1_000_000
SEEDS = [1, 2]
HORIZONS = [2000, 10000]
SHARES = [1.0, 0.7, 0.5]  # the pick's cost limit as a share of the task's
# (algo, task): the groups of results/table1_v2 with a last policy or a pick over the limit
# (docs/table1_v2/before_after_*.md), the largest misses first.
GROUPS = [
    ("sac_lag", "SafetyCarCircle1-v0"),  # seed 10: 164.5; 30: 21.0
    ("s3rl", "SafetyHopperVelocity-v1"),  # seed 20: 31.9
    ("sac_lag", "SafetySwimmerVelocity-v1"),  # seed 20: 39.6
    ("s3rl", "SafetySwimmerVelocity-v1"),  # seed 30: 25.9
    ("sac_lag", "SafetyAntRun-v0"),  # seed 20: 22.1; its seed 30 pick 10.1
    ("sac_lag", "SafetyHopperVelocity-v1"),  # seed 30: 21.5
    ("s3rl", "SafetyPointCircle1-v0"),  # seed 30's pick: 19.7
    ("s3rl", "SafetyAntCircle-v0"),  # seed 20's pick: 18.3
    ("sac_lag", "SafetyCarCircle-v0"),  # seed 30: 17.7
    ("sac_lag", "SafetyWalker2dVelocity-v1"),  # seed 30: 15.3
    ("s3rl", "SafetyAntVelocity-v1"),  # seed 20: 14.9
    ("s3rl", "SafetyWalker2dVelocity-v1"),  # seed 20: 14.1
    ("sac_lag", "SafetyBallCircle-v0"),  # seed 30: 10.7
    ("sac_lag", "SafetyAntVelocity-v1"),  # seed 10: 10.1
    ("sac_lag", "SafetyBallRun-v0"),  # seed 30: 88.0, over in training too
]
RECORDING = [
    "eval.delivery_report_all=true",
    f"eval.ema_horizons=[{','.join(str(h) for h in HORIZONS)}]",
]


def jobs(out: Path):
    """Seed 1 of every group, then seed 2."""
    for seed in SEEDS:
        for algo, task in GROUPS:
            run_dir = out / f"{algo}_{task}" / f"seed{seed}"
            yield queued_run(run_dir, task, algo, seed, FRAMES, *RECORDING)


# ----------------------------------------------------------------------------- the rules
def protocols() -> list[str]:
    return ["last", *(f"pick{share:g}" for share in SHARES), *(f"ema{h}" for h in HORIZONS)]


def delivered(final: dict, protocol: str, cost_limit: float) -> tuple[float, float] | None:
    """(reward, cost) the rule ``protocol`` delivers for a run of a task with ``cost_limit``,
    on episodes it was not chosen on."""
    if protocol == "last":
        return final["reward_mean"], final["cost_mean"]
    if protocol.startswith("ema"):
        entry = final.get(protocol)
        return None if entry is None else (entry["reward_mean"], entry["cost_mean"])
    share = float(protocol.removeprefix("pick"))
    record = final.get("delivered")
    if record is None:
        return None
    if share == 1.0:  # the preset's own pick, reported by the run itself
        return record["reward_mean"], record["cost_mean"]
    candidates = record["candidates"]
    # The run's own rule (trainer.evaluation.pick_delivered) on the candidates' picking numbers.
    readings = [SimpleNamespace(reward_mean=c["reward"], cost_mean=c["cost"]) for c in candidates]
    index, _ = pick_delivered(readings, share * cost_limit)
    chosen = candidates[index]
    return chosen["report_reward"], chosen["report_cost"]


def summarise(root: Path) -> str:
    runs = [run for run in find_runs(root) if run.finished]
    means = committed_rewards()
    names = protocols()
    lines = [
        "| algo | task | seed | " + " | ".join(names) + " | eval cost, last 20%: mean / sd / "
        "over | " + " | ".join(f"{h} mean / sd / over" for h in (f"ema{h}" for h in HORIZONS)) + " |",
        "|" + "---|" * (4 + len(names) + len(HORIZONS)),
    ]
    tally = {name: {"within": 0, "runs": 0, "ratios": []} for name in names}
    for run in sorted(runs, key=lambda r: (r.algo, r.task, r.seed)):
        limit = run.cost_limit
        cells = []
        for name in names:
            value = delivered(run.final, name, limit)
            if value is None:
                cells.append("–")
                continue
            reward, cost = value
            cells.append(f"{reward:.1f} / {cost:.1f}")
            tally[name]["runs"] += 1
            tally[name]["within"] += cost <= limit
            base = means.get((run.algo, run.task))
            if base:
                tally[name]["ratios"].append(reward / base)
        spreads = []
        for column in ["eval/cost", *(f"ema{h}/cost" for h in HORIZONS)]:
            values = tail(run, column)
            spreads.append(
                f"{values.mean():.1f} / {values.std():.1f} / {int((values > limit).sum())} of "
                f"{values.size}" if values.size else "–"
            )
        lines.append(f"| {run.algo} | {run.task} | {run.seed} | " + " | ".join(cells + spreads) + " |")
    lines += ["", "| rule | within the limit | reward / committed mean (median) |", "|---|---|---|"]
    for name in names:
        t = tally[name]
        ratio = f"{np.median(t['ratios']):.2f}" if t["ratios"] else "–"
        lines.append(f"| {name} | {t['within']} of {t['runs']} | {ratio} |")
    expected = len(SEEDS) * len(GROUPS)
    if len(runs) < expected:  # the rule reads the whole round, never a part of it
        lines += ["", f"The rule's choice: not yet ({len(runs)} of {expected} runs finished)."]
    else:
        lines += ["", choice(tally)]
    return "\n".join(lines) + "\n"


def choice(tally: dict[str, dict]) -> str:
    """The rule of research/2026-12-04-delivery-rules.md, applied to the tally: the most runs
    within the limit, a tie to the higher median reward ratio, a ratio below 0.85 passed over;
    the preset's pick (`pick1`) is replaced only by a rule with at least 2 more runs within."""
    def ratio(name):
        return float(np.median(tally[name]["ratios"])) if tally[name]["ratios"] else 0.0

    eligible = [name for name in tally if tally[name]["runs"] and ratio(name) >= 0.85]
    if not eligible:
        return "The rule's choice: none (no rule keeps 0.85 of the reward)."
    best = max(eligible, key=lambda name: (tally[name]["within"], ratio(name)))
    preset = tally.get("pick1", {"within": 0})["within"]
    if best != "pick1" and tally[best]["within"] < preset + 2:
        return (
            f"The rule's choice: pick1, the preset's pick, kept ({best} keeps "
            f"{tally[best]['within']} of {tally[best]['runs']}, fewer than 2 more than its {preset})."
        )
    return (
        f"The rule's choice: {best} ({tally[best]['within']} of {tally[best]['runs']} within the "
        f"limit, reward ratio {ratio(best):.2f})."
    )


def main() -> None:
    run_or_summarise(__doc__.splitlines()[0], jobs, summarise)


if __name__ == "__main__":
    main()
