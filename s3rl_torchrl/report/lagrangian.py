"""How the Lagrange multiplier and the cost behave over training: ``s3rl-report lagrangian``.

    s3rl-report lagrangian RUN_DIR... [--out lagrangian.json] [--csv-dir DIR] [--plot lagrangian.png]
        [--until FRAMES]

Reads any ``s3rl-train`` run directories (``config.json``, ``metrics.csv``, ``final_eval.json``
if the run finished, and the CSV logger's ``lagrangian/value`` if the run kept it). Per run, over
the second half of training (epochs whose frame count is above half the last one): the fraction
of epochs whose evaluation cost and whose training-episode cost exceed the limit, and of those
where the two fall on opposite sides of it (``train_over_eval_within``,
``train_within_eval_over``: the multiplier is fed the stochastic policy's training cost, the
targets read the deterministic evaluation), the mean
|delta lambda| between consecutive epochs and, when the run kept torchrl's CSV log
(``logger=csv``, the default), between consecutive lambda updates; the mean evaluation and
training reward and cost; the lag-1 autocorrelation of the training cost (what the controller
is fed; about -1 in a period-2 cycle); the mean evaluation reward and cost over the last 20% of
epochs; the final evaluation if there is one. Where the multiplier lets go: the lowest lambda,
the share of epochs that end with lambda below ``LAMBDA_NEAR_ZERO`` (0.05) and the share of those
whose evaluation is over the limit, and the mean evaluation reward of the epochs over the limit
and of those within it. Runs are grouped by task, algo and controller
setting (read from each run's ``config.json``) and the means and standard deviations over seeds
written to ``--out`` with the command that made them. ``--csv-dir`` copies each run's
``metrics.csv`` (a few kB) there as ``<task>/[<algo>/]<setting>/seed<seed>.csv`` (the setting's
name with ``_`` for punctuation; the algo level for any algo but SAC-Lag). ``--plot`` draws
lambda and the cost against frames, a pair of rows per setting and a column per seed.
``--until FRAMES`` reads every run as if it had stopped at ``FRAMES`` (its epochs up to there,
its lambda updates up to there, no final evaluation): a 1M-frame run then counts as a
300k-frame run of the same setting.

``make report`` runs it on the runs kept in ``results/`` (docs/results.md); the study that
launches the runs of a controller comparison and the synthetic plant are
``research/studies/lagrangian_dynamics.py``.
"""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
import sys
import textwrap
from collections import defaultdict
from pathlib import Path

from s3rl_torchrl.algorithms.config import REMOVED_OPTIONS
from s3rl_torchrl.report.records import write_json
from s3rl_torchrl.report.runs import late_epochs

__all__ = [
    "METRICS",
    "aggregate",
    "lag1_autocorrelation",
    "markdown",
    "plot",
    "setting_name",
    "summarise",
    "summarise_run",
]


def algo_dir(root: Path, task: str, algo: str) -> Path:
    """``<root>/<task>`` for SAC-Lag (the original layout), ``<root>/<task>/<algo>`` for any
    other algo: the launcher's runs and the copied CSVs alike."""
    return root / task if algo == "sac_lag" else root / task / algo



METRICS = (
    "eval_cost_over_limit",
    "train_cost_over_limit",
    "train_over_eval_within",
    "train_within_eval_over",
    "mean_abs_dlambda_epoch",
    "mean_abs_dlambda_update",
    "lambda_mean",
    "lambda_min",
    "lambda_near_zero",
    "eval_cost_over_limit_near_zero",
    "eval_reward_over_limit",
    "eval_reward_within_limit",
    "eval_reward",
    "eval_cost",
    "train_reward",
    "train_cost",
    "train_cost_autocorr",
    "eval_reward_last20",
    "eval_cost_last20",
    "train_cost_last20",
    "lambda_peak",
    "lambda_peak_frames",
    "lambda_end",
    "final_reward",
    "final_cost",
)


#: Below this the multiplier counts as released: the policy's loss is then about SAC's.
LAMBDA_NEAR_ZERO = 0.05


def _float(value: str | None) -> float:
    try:
        return float(value) if value not in (None, "") else math.nan
    except ValueError:
        return math.nan


def _mean(values: list[float]) -> float:
    values = [v for v in values if not math.isnan(v)]
    return sum(values) / len(values) if values else math.nan


def _std(values: list[float]) -> float:
    values = [v for v in values if not math.isnan(v)]
    if len(values) < 2:
        return math.nan
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1))


def lag1_autocorrelation(values: list[float]) -> float:
    """Lag-1 autocorrelation of a series (the usual ACF estimate: deviations from the mean of
    the series, over its variance), from consecutive pairs that are both numbers. A period-2
    cycle (high, low, high, ...) gives about -1; a settled or slowly drifting series >= 0."""
    present = [v for v in values if not math.isnan(v)]
    if len(present) < 3:
        return math.nan
    mean = sum(present) / len(present)
    variance = sum((v - mean) ** 2 for v in present)
    if variance == 0:
        return math.nan
    pairs = [(a, b) for a, b in zip(values, values[1:]) if not (math.isnan(a) or math.isnan(b))]
    return sum((a - mean) * (b - mean) for a, b in pairs) / variance


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def setting_name(config: dict) -> str:
    """The controller setting of a run: the Lagrangian, its options and the collect size."""
    algo, collector = config["algo"], config["collector"]
    kind = algo["lagrangian"]
    if kind == "pid":
        pid = algo["pid"]
        name = f"pid(kp={pid['kp']},ki={pid['ki']},kd={pid['kd']}"
        if pid["ema_alpha"] or pid["derivative_delay"] != 1:
            name += f",ema={pid['ema_alpha']},delay={pid['derivative_delay']}"
        if pid["penalty_max"] is not None:
            name += f",max={pid['penalty_max']}"
        name += ")"
    elif kind == "learned":
        name = f"learned(lr={algo['lagrangian_lr']})"
    else:
        name = kind
    if algo.get("lagrangian_cadence", "collect") == "step":  # runs before the option: collect
        name += (
            f" step(window={algo['lagrangian_window']},"
            f"warmup={algo['lagrangian_warmup_frames']})"
        )
    name += _critic_setting(algo)
    return f"{name} batch={collector['frames_per_batch']}"


# FSRL's cost critics (critic=fsrl), which runs from before the option also had.
_FSRL_CRITICS = {"cost_critic_read": "min", "cost_nonnegative": False, "cost_entropy": True,
                 "entropy_rescaling": True}


def _critic_setting(algo: dict) -> str:
    """What else a SAC-family selection varies, when it differs from FSRL's and the paper's:
    the cost critics (``critic=sound`` is ``sound(read=max)``), an option that has since left
    the package (``REMOVED_OPTIONS``) at another value than its default, the gradient steps
    per frame (the paper's 0.2). Empty for the paper's runs with FSRL's critics."""
    label = ""
    if "cost_critic_read" in algo:
        critics = {key: algo.get(key, default) for key, default in _FSRL_CRITICS.items()}
        # The targets' own read (cost_target_read), when it differs from the actor loss's.
        read = critics["cost_critic_read"]
        target = algo.get("cost_target_read") or read
        if critics != _FSRL_CRITICS or target != read:
            sound = critics["cost_nonnegative"] and not critics["cost_entropy"]
            sound = sound and not critics["entropy_rescaling"]
            targets = f",target={target}" if target != read else ""
            label += f" {'sound' if sound else 'critic'}(read={read}{targets})"
    for name, option in REMOVED_OPTIONS.items():  # the runs made before it left
        if algo.get(name, option.default) != option.default:
            label += f" {name}={algo[name]}"
    if "cost_critic_read" in algo and algo.get("update_per_step", 0.2) != 0.2:
        label += f" ups={algo['update_per_step']}"
    return label


def lambda_updates(run_dir: Path) -> list[tuple[float, float]]:
    """(frames, lambda) after each update, from torchrl's CSV logger if the run used it."""
    files = sorted(run_dir.glob("logs/*/scalars/lagrangian/value.csv"))
    if not files:
        return []
    with files[0].open(newline="") as f:
        return [(float(r[0]), float(r[1])) for r in csv.reader(f) if len(r) >= 2]


def summarise_run(run_dir: Path, until: int | None = None) -> dict:
    """One run's second-half statistics (see the module docstring); with ``until``, of its
    epochs up to that many frames, as if it had stopped there."""
    config = json.loads((run_dir / "config.json").read_text())
    rows = read_rows(run_dir / "metrics.csv")
    if until is not None:
        rows = [r for r in rows if _float(r["frames"]) <= until]
    if not rows:
        raise ValueError(f"{run_dir}: metrics.csv has no epoch yet")
    limit = float(config["task"]["cost_limit"])
    frames = [_float(r["frames"]) for r in rows]
    half = frames[-1] / 2
    late = [r for r, f in zip(rows, frames) if f > half]
    last20 = late_epochs(rows)  # the targets' window
    col = {key: [_float(r.get(key)) for r in late] for key in rows[0]}

    def over(values: list[float]) -> float:
        values = [v for v in values if not math.isnan(v)]
        return sum(v > limit for v in values) / len(values) if values else math.nan

    def split(train_over: bool) -> float:
        pairs = [(t, e) for t, e in zip(col["train/cost"], col["eval/cost"])
                 if not (math.isnan(t) or math.isnan(e))]
        hits = sum((t > limit) == train_over and (e > limit) != train_over for t, e in pairs)
        return hits / len(pairs) if pairs else math.nan

    lams = col["lagrangian"]
    known = [lam for lam in lams if not math.isnan(lam)]
    evals = [(lam, r, c) for lam, r, c in zip(lams, col["eval/reward"], col["eval/cost"])
             if not math.isnan(c)]
    lambda_peak, peak_frames = max(
        ((_float(r.get("lagrangian")), f) for r, f in zip(rows, frames)),
        key=lambda pair: -math.inf if math.isnan(pair[0]) else pair[0],
    )
    updates = [lam for f, lam in lambda_updates(run_dir) if half < f <= frames[-1]]
    summary = {
        "run_dir": str(run_dir),
        "task": config["task"]["name"],
        "algo": config["algo"]["name"],
        "setting": setting_name(config),
        "seed": config["seed"],
        "cost_limit": limit,
        "frames": int(frames[-1]),
        "epochs_second_half": len(late),
        "eval_cost_over_limit": over(col["eval/cost"]),
        "train_cost_over_limit": over(col["train/cost"]),
        # The multiplier is fed the training episodes' cost (the stochastic policy's); the
        # targets read the deterministic evaluation. The share of epochs where the two fall on
        # opposite sides of the limit, each way round.
        "train_over_eval_within": split(train_over=True),
        "train_within_eval_over": split(train_over=False),
        "mean_abs_dlambda_epoch": _mean([abs(b - a) for a, b in zip(lams, lams[1:])]),
        "mean_abs_dlambda_update": _mean([abs(b - a) for a, b in zip(updates, updates[1:])]),
        "lambda_mean": _mean(lams),
        # Whether the evaluations over the limit come where the multiplier has let go (a cycle
        # that takes lambda back to about 0), and what they earn beside those within it.
        "lambda_min": min(known, default=math.nan),
        "lambda_near_zero": _mean([float(lam < LAMBDA_NEAR_ZERO) for lam in known]),
        "eval_cost_over_limit_near_zero": over(
            [c for lam, _, c in evals if lam < LAMBDA_NEAR_ZERO]
        ),
        "eval_reward_over_limit": _mean([r for _, r, c in evals if c > limit]),
        "eval_reward_within_limit": _mean([r for _, r, c in evals if c <= limit]),
        "eval_reward": _mean(col["eval/reward"]),
        "eval_cost": _mean(col["eval/cost"]),
        "train_reward": _mean(col["train/reward"]),
        "train_cost": _mean(col["train/cost"]),
        # The controller's input from one collect to the next: about -1 in the period-2 cycle.
        "train_cost_autocorr": lag1_autocorrelation(col["train/cost"]),
        "eval_reward_last20": _mean([_float(r.get("eval/reward")) for r in last20]),
        "eval_cost_last20": _mean([_float(r.get("eval/cost")) for r in last20]),
        "train_cost_last20": _mean([_float(r.get("train/cost")) for r in last20]),
        # Over the whole run, not its second half: how high the multiplier went, when, and
        # where it ended (the per-task tables of research/2026-11-26-sound-critics-evidence.md).
        "lambda_peak": lambda_peak,
        "lambda_peak_frames": int(peak_frames),
        "lambda_end": _float(rows[-1].get("lagrangian")),
        "final_reward": math.nan,
        "final_cost": math.nan,
    }
    final = run_dir / "final_eval.json"
    if final.exists() and until is None:
        result = json.loads(final.read_text())
        summary["final_reward"] = result["reward_mean"]
        summary["final_cost"] = result["cost_mean"]
    return summary


def aggregate(runs: list[dict]) -> list[dict]:
    """Mean and standard deviation over seeds, per (task, algo, setting)."""
    groups: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    for run in runs:
        groups[run["task"], run["algo"], run["setting"]].append(run)
    table = []
    for (task, algo, setting), members in sorted(groups.items()):
        row = {"task": task, "algo": algo, "setting": setting}
        row["seeds"] = sorted(m["seed"] for m in members)
        row["frames"] = min(m["frames"] for m in members)
        for key in METRICS:
            values = [m[key] for m in members]
            row[key] = _mean(values)
            row[key + "_std"] = _std(values)
        table.append(row)
    return table


def _pm(row: dict, key: str, digits: int) -> str:
    """``mean ± std`` over seeds (the std left out for one seed), ``–`` without a value."""
    mean, std = row[key], row[key + "_std"]
    if math.isnan(mean):
        return "–"
    return f"{mean:.{digits}f}" + ("" if math.isnan(std) else f" ± {std:.{digits}f}")


def markdown(table: list[dict]) -> str:
    head = (
        "| task | algo | setting | seeds | frames | eval cost > d | train cost > d | mean abs "
        "dlambda (epoch) | lambda | eval reward | eval cost | train cost lag-1 autocorr | "
        "eval reward (last 20%) | eval cost (last 20%) | final reward | final cost |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in table:
        lines.append(
            f"| {r['task']} | {r['algo']} | {r['setting']} | {len(r['seeds'])} | {r['frames']} | "
            f"{r['eval_cost_over_limit']:.2f} | {r['train_cost_over_limit']:.2f} | "
            f"{r['mean_abs_dlambda_epoch']:.3g} | {r['lambda_mean']:.3g} | "
            f"{r['eval_reward']:.0f} | {r['eval_cost']:.1f} | {r['train_cost_autocorr']:.2f} | "
            f"{r['eval_reward_last20']:.0f} | {r['eval_cost_last20']:.1f} | "
            f"{_pm(r, 'final_reward', 0)} | {_pm(r, 'final_cost', 1)} |"
        )
    return "\n".join(lines)


def copy_metrics(runs: list[dict], csv_dir: Path) -> None:
    for run in runs:
        slug = re.sub(r"[^A-Za-z0-9.]+", "_", run["setting"]).strip("_")
        target = algo_dir(csv_dir, run["task"], run["algo"]) / slug / f"seed{run['seed']}.csv"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(Path(run["run_dir"]) / "metrics.csv", target)


def plot(runs: list[dict], path: Path):
    """Lambda and cost (evaluation and training episodes) against frames: one pair of rows
    (lambda above cost) per task, algo and setting, one column per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[tuple, list[dict]] = {}
    for run in runs:
        groups.setdefault((run["task"], run["algo"], run["setting"]), []).append(run)
    columns = max(len(g) for g in groups.values())
    fig, axes = plt.subplots(2 * len(groups), columns, figsize=(4 * columns, 5 * len(groups)),
                             squeeze=False)
    for ax in axes.flat:
        ax.set_visible(False)
    for i, group in enumerate(groups.values()):
        for j, run in enumerate(sorted(group, key=lambda r: r["seed"])):
            top, bottom = axes[2 * i, j], axes[2 * i + 1, j]
            top.set_visible(True)
            bottom.set_visible(True)
            rows = read_rows(Path(run["run_dir"]) / "metrics.csv")
            frames = [_float(r["frames"]) / 1e3 for r in rows]
            top.plot(frames, [_float(r["lagrangian"]) for r in rows], "k.-")
            title = f"{run['task'].replace('Safety', '')} {run['algo']} seed {run['seed']}\n"
            title += textwrap.fill(run["setting"].replace(",", ", "), 60)
            top.set_title(title, fontsize=8)
            top.set_ylabel("lambda after the update")
            bottom.plot(frames, [_float(r["eval/cost"]) for r in rows], "r.-", label="eval")
            bottom.plot(frames, [_float(r["train/cost"]) for r in rows], "b.-", label="train")
            bottom.axhline(run["cost_limit"], color="gray", ls="--", label="limit")
            bottom.set_yscale("symlog", linthresh=10)
            bottom.set_ylim(bottom=0)
            bottom.set_xlabel("frames (k)")
            bottom.set_ylabel("episode cost")
            bottom.legend(fontsize=6)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f"wrote {path}")
    return fig


def summarise(
    run_dirs: list[Path],
    out: Path | None,
    csv_dir: Path | None,
    plot_path,
    until=None,
    command: str | None = None,
) -> dict:
    """Summarise ``run_dirs`` (those without ``metrics.csv`` are skipped with a note), print the
    table, write ``out`` (JSON: the runs and the settings, with ``command``: by default the
    command line of this process), copy the metrics to ``csv_dir`` and draw ``plot_path``."""
    runs = []
    for run_dir in run_dirs:
        if not (run_dir / "metrics.csv").exists():
            print(f"skipping {run_dir}: no metrics.csv", file=sys.stderr)
            continue
        runs.append(summarise_run(run_dir, until))
    table = aggregate(runs)
    print(markdown(table))
    report = {"runs": runs, "settings": table}
    if out is not None:
        write_json(out, report, command or "python " + " ".join(sys.argv))
    if csv_dir is not None:
        copy_metrics(runs, csv_dir)
    if plot_path is not None and runs:
        plot(runs, plot_path)
    return report
