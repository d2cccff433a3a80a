"""How the Lagrange multiplier and the cost behave over training, per controller setting.

Summarise finished (or running) runs, any ``s3rl-train`` run directories::

    python benchmarks/lagrangian_dynamics.py summarise outputs/sac_lag/*/seed*/* \\
        [--out benchmarks/results/lagrangian_dynamics.json] [--csv-dir results/lagrangian] \\
        [--plot docs/figures/lagrangian_dynamics.png]

or launch ``seeds x settings x tasks`` runs first (one ``s3rl-train`` process each, ``--jobs``
at a time; an existing run directory is resumed, a finished one skipped), then summarise::

    python benchmarks/lagrangian_dynamics.py launch --tasks SafetyHalfCheetahVelocity-v1 \\
        --settings fsrl pid_ema --seeds 10 20 30 --frames 300000 --runs-dir runs/lagrangian

With ``--group`` the seeds of a task and setting train in ONE process (``s3rl-train
'seeds=[10,20,30]'``, the multi-seed trainer), written to
``<runs-dir>/<task>/<setting>/seed<k>/`` and resumed as a group. The runs are SAC-Lag's;
``--algo s3rl`` runs S3RL instead, into ``<runs-dir>/<task>/s3rl/<setting>/``.

``summarise --until FRAMES`` reads every run as if it had stopped at ``FRAMES`` (its epochs up to
there, its lambda updates up to there, no final evaluation): a 1M-frame run then counts as a
300k-frame run of the same setting.

or run the controllers of those settings on the synthetic plant of the unit tests instead of a
policy (``J_{t+1} = max(0, J0 - k lambda_t + noise)``, no training, seconds)::

    python benchmarks/lagrangian_dynamics.py plant [--updates 50] [--noise 20] [--k 486]

Per run, over the second half of training (epochs whose frame count is above half the last
one): the fraction of epochs whose evaluation cost and whose training-episode cost exceed the
limit, the mean |delta lambda| between consecutive epochs and, when the run kept torchrl's CSV
log (``logger=csv``, the default), between consecutive lambda updates; the mean evaluation and
training reward and cost; the lag-1 autocorrelation of the training cost (what the controller
is fed; about -1 in a period-2 cycle); the final evaluation if there is one. Runs are grouped by task and
controller setting (read from each run's ``config.json``) and the means and standard deviations
over seeds written to ``--out``. ``--csv-dir`` copies each run's ``metrics.csv`` (a few kB)
there as ``<task>/<setting>/seed<seed>.csv`` (the setting's name with ``_`` for punctuation).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
import textwrap
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import write_report  # noqa: E402

STEP = [
    "algo.lagrangian_cadence=step",
    "algo.lagrangian_window=20",
    "algo.lagrangian_warmup_frames=${collector.init_random_frames}",
]
# Controller settings of the comparison, as s3rl-train overrides on top of
# experiment=paper (--experiment) algo=sac_lag (--algo); frames_per_epoch stays the experiment's.
SETTINGS: dict[str, list[str]] = {
    # Every setting names its controller (algo.lagrangian): pid=... sets only the gains, and
    # experiment=safe picks `learned`.
    # The paper's PID in FSRL's form, one update per 20-episode collect.
    "fsrl": ["algo.lagrangian=pid", "pid=fsrl"],
    # The same gains, OmniSafe's EMA of error and cost, delay 10.
    "pid_ema": ["algo.lagrangian=pid", "pid=ema"],
    # Twice as many updates (10 episodes each, 2000 gradient steps between them): the schedule
    # of the first cycling runs. With 10 envs in lockstep on 1000-step episodes a smaller batch
    # does not update more often: episodes only end every 10000 frames. Warm-up and evaluation
    # cadence stay those of the 20000-frame collects (the 1000-step tasks), for comparability.
    "fsrl_10k": [
        "algo.lagrangian=pid",
        "pid=fsrl",
        "collector.frames_per_batch=10000",
        "collector.init_random_frames=20000",
        "collector.frames_per_epoch=20000",
    ],
    "learned": ["algo.lagrangian=learned"],  # Adam on lambda (J - d), OmniSafe's SACLag
    # pid_ema with a 20x integral gain: with ki = 0.0005 the integral adds ~0.025 to lambda per
    # update at an error of 50, so over 15-50 updates pid_ema is a P controller whose cost
    # settles at lambda / kp above the limit; a larger ki is what can close that offset.
    "pid_ema_ki0.01": ["algo.lagrangian=pid", "pid=ema", "algo.pid.ki=0.01"],
    # OmniSafe's cadence (algo.lagrangian_cadence=step): lambda moves after every gradient step,
    # from the mean cost of the last 20 finished training episodes (one FSRL collect's worth),
    # frozen while the collector still acts at random (the first collect). Rates and gains are
    # per gradient step; the selection sweep of docs/results.md ("Holding the limit").
    "step_learned_lr1e-4": ["algo.lagrangian=learned", "algo.lagrangian_lr=0.0001", *STEP],
    "step_learned_lr3e-4": ["algo.lagrangian=learned", "algo.lagrangian_lr=0.0003", *STEP],
    # OmniSafe's SACPID (configs/pid/omnisafe.yaml) with its integral gain per env step (1e-7)
    # scaled to the paper's 0.2 gradient steps per env step: the same lambda per frame.
    "step_pid_omnisafe": ["algo.lagrangian=pid", "pid=omnisafe", "algo.pid.ki=5e-7", *STEP],
    # The controllers alone, for --experiment safe (configs/experiment/safe.yaml: the step
    # cadence above and 1000-frame collects); the second round of the selection.
    "learned_lr3e-4": ["algo.lagrangian=learned", "algo.lagrangian_lr=0.0003"],
    "pid_omnisafe": ["algo.lagrangian=pid", "pid=omnisafe", "algo.pid.ki=5e-7"],
}
BASE_OVERRIDES = ["threads=1", "logger.progress_bar=false"]
LAGRANGIAN_ALGOS = ("sac_lag", "s3rl")  # the off-policy SAC pair whose schedule this studies


def algo_dir(root: Path, task: str, algo: str) -> Path:
    """``<root>/<task>`` for SAC-Lag (the original layout), ``<root>/<task>/<algo>`` for any
    other algo: the launcher's runs and the copied CSVs alike."""
    return root / task if algo == "sac_lag" else root / task / algo


def setting_dir(runs_dir: Path, task: str, algo: str, setting: str) -> Path:
    """Where the launcher puts a task, algo and setting's runs."""
    return (algo_dir(runs_dir, task, algo) / setting).resolve()


METRICS = (
    "eval_cost_over_limit",
    "train_cost_over_limit",
    "mean_abs_dlambda_epoch",
    "mean_abs_dlambda_update",
    "lambda_mean",
    "eval_reward",
    "eval_cost",
    "train_reward",
    "train_cost",
    "train_cost_autocorr",
    "eval_reward_last20",
    "eval_cost_last20",
    "final_reward",
    "final_cost",
)


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
    return f"{name} batch={collector['frames_per_batch']}"


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
    # The targets' window (docs/results.md, "Holding the limit"): the last 20% of epochs.
    last20 = rows[-max(1, round(0.2 * len(rows))):]
    col = {key: [_float(r.get(key)) for r in late] for key in rows[0]}

    def over(values: list[float]) -> float:
        values = [v for v in values if not math.isnan(v)]
        return sum(v > limit for v in values) / len(values) if values else math.nan

    lams = col["lagrangian"]
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
        "mean_abs_dlambda_epoch": _mean([abs(b - a) for a, b in zip(lams, lams[1:])]),
        "mean_abs_dlambda_update": _mean([abs(b - a) for a, b in zip(updates, updates[1:])]),
        "lambda_mean": _mean(lams),
        "eval_reward": _mean(col["eval/reward"]),
        "eval_cost": _mean(col["eval/cost"]),
        "train_reward": _mean(col["train/reward"]),
        "train_cost": _mean(col["train/cost"]),
        # The controller's input from one collect to the next: about -1 in the period-2 cycle.
        "train_cost_autocorr": lag1_autocorrelation(col["train/cost"]),
        "eval_reward_last20": _mean([_float(r.get("eval/reward")) for r in last20]),
        "eval_cost_last20": _mean([_float(r.get("eval/cost")) for r in last20]),
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
    run_dirs: list[Path], out: Path | None, csv_dir: Path | None, plot_path, until=None
) -> dict:
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
        write_report(out, report)
    if csv_dir is not None:
        copy_metrics(runs, csv_dir)
    if plot_path is not None and runs:
        plot(runs, plot_path)
    return report


def launch(args: argparse.Namespace) -> list[Path]:
    """Run (or resume) every task x setting x seed with s3rl-train, ``--jobs`` at a time."""
    path = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PYTHONPATH=path)
    todo, run_dirs = [], []
    for task in args.tasks:
        for setting in args.settings:
            if args.group:
                group_dir = setting_dir(args.runs_dir, task, args.algo, setting)
                seed_dirs = [group_dir / f"seed{seed}" for seed in args.seeds]
                run_dirs.extend(seed_dirs)
                if all((d / "final_eval.json").exists() for d in seed_dirs):
                    continue
                seeds = ",".join(map(str, args.seeds))
                overrides = [
                    f"experiment={args.experiment}",
                    f"algo={args.algo}",
                    *BASE_OVERRIDES,
                    *SETTINGS[setting],
                    f"task={task}",
                    f"seeds=[{seeds}]",
                    f"collector.total_frames={args.frames}",
                    f"compile={str(args.compile).lower()}",
                    *args.override,
                ]
                if (group_dir / "seeds.json").exists():
                    overrides.append(f"resume={group_dir}")
                overrides.append(f"hydra.run.dir={group_dir}")
                todo.append((group_dir, [sys.executable, "-m", "recipes.train", *overrides]))
                continue
            for seed in args.seeds:
                run_dir = setting_dir(args.runs_dir, task, args.algo, setting) / f"seed{seed}"
                run_dirs.append(run_dir)
                if (run_dir / "final_eval.json").exists():
                    continue
                overrides = [
                    f"experiment={args.experiment}",
                    f"algo={args.algo}",
                    *BASE_OVERRIDES,
                    *SETTINGS[setting],
                    f"task={task}",
                    f"seed={seed}",
                    f"collector.total_frames={args.frames}",
                    f"compile={str(args.compile).lower()}",
                    *args.override,
                ]
                if (run_dir / "checkpoints" / "latest").exists():
                    overrides.append(f"resume={run_dir}")
                overrides.append(f"hydra.run.dir={run_dir}")
                todo.append((run_dir, [sys.executable, "-m", "recipes.train", *overrides]))
    running: list[tuple[Path, subprocess.Popen]] = []
    while todo or running:
        while todo and len(running) < args.jobs:
            run_dir, cmd = todo.pop(0)
            run_dir.mkdir(parents=True, exist_ok=True)
            print("launch:", " ".join(cmd[3:]), flush=True)
            log = (run_dir / "launch.log").open("a")
            process = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=log, stderr=log)
            running.append((run_dir, process))
        for item in list(running):
            if item[1].poll() is not None:
                running.remove(item)
                print(f"done ({item[1].returncode}): {item[0]}", flush=True)
        time.sleep(0.5)
    return run_dirs


def plant_settings() -> dict[str, Callable[[float], object]]:
    """The controllers of SETTINGS as s3rl-train builds them (the collect size aside), and the
    learned multiplier with a 10x larger step."""
    from hydra import compose, initialize_config_dir

    from s3rl_torchrl.algorithms import build_lagrangian
    from s3rl_torchrl.trainer import register_configs, validate

    register_configs()
    settings = {name: SETTINGS[name] for name in ("fsrl", "pid_ema", "pid_ema_ki0.01", "learned")}
    settings["learned_lr0.05"] = [*SETTINGS["learned"], "algo.lagrangian_lr=0.05"]
    made = {}
    with initialize_config_dir(config_dir=str(REPO / "configs"), version_base="1.3"):
        for name, overrides in settings.items():
            overrides = ["algo=sac_lag", *BASE_OVERRIDES, *overrides]
            cfg = validate(compose(config_name="train", overrides=overrides))
            made[name] = lambda limit, algo=cfg.algo: build_lagrangian(algo, limit)
    return made


def run_plant(args: argparse.Namespace) -> dict:
    """Second-half statistics of each controller on the synthetic plant, per seed and mean."""
    import numpy as np

    rows = []
    for name, make in plant_settings().items():
        per_seed = []
        for seed in args.seeds:
            controller, rng = make(args.limit), np.random.default_rng(seed)
            lam, costs, lams = float(controller.lagrangian[0]), [], []
            for _ in range(args.updates):
                cost = max(0.0, args.j0 - args.k * lam + args.noise * rng.standard_normal())
                lam = float(controller.update(cost)[0])
                costs.append(cost)
                lams.append(lam)
            late_cost, late_lam = costs[args.updates // 2 :], lams[args.updates // 2 :]
            per_seed.append(
                {
                    "cost_over_limit": _mean([float(c > args.limit) for c in late_cost]),
                    "mean_abs_dlambda": _mean(
                        [abs(b - a) for a, b in zip(late_lam, late_lam[1:])]
                    ),
                    "cost": _mean(late_cost),
                    "lambda": _mean(late_lam),
                    "first_lambdas": [round(v, 3) for v in lams[:6]],
                }
            )
        row = {"setting": name, "seeds": list(args.seeds)}
        for key in ("cost_over_limit", "mean_abs_dlambda", "cost", "lambda"):
            row[key] = _mean([s[key] for s in per_seed])
        row["first_lambdas_seed0"] = per_seed[0]["first_lambdas"]
        rows.append(row)
    print(f"plant: J = max(0, {args.j0} - {args.k} lambda + N(0, {args.noise}^2)), d = "
          f"{args.limit}, {args.updates} updates, second half, mean over seeds {args.seeds}")
    print("| setting | cost > d | mean abs dlambda | mean cost | mean lambda | first lambdas |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['setting']} | {r['cost_over_limit']:.2f} | {r['mean_abs_dlambda']:.3g} | "
              f"{r['cost']:.1f} | {r['lambda']:.3g} | {r['first_lambdas_seed0']} |")
    plant = {k: getattr(args, k) for k in ("j0", "k", "noise", "limit", "updates")}
    report = {"plant": plant, "settings": rows}
    if args.out is not None:
        write_report(args.out, report)
    return report


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    for mode in ("summarise", "launch"):
        p = sub.add_parser(mode)
        p.add_argument("--out", type=Path, default=None, help="JSON summary")
        p.add_argument("--csv-dir", type=Path, default=None, help="copy metrics.csv files here")
        p.add_argument("--plot", type=Path, default=None, help="lambda and cost figure (PNG)")
    sub.choices["summarise"].add_argument("run_dirs", nargs="+", type=Path)
    sub.choices["summarise"].add_argument(
        "--until", type=int, default=None, help="read runs as if stopped at this many frames"
    )
    p = sub.choices["launch"]
    p.add_argument("--tasks", nargs="+", default=["SafetyHalfCheetahVelocity-v1"])
    p.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS))
    p.add_argument("--seeds", nargs="+", type=int, default=[10, 20, 30])
    p.add_argument("--frames", type=int, default=300_000)
    p.add_argument("--experiment", default="paper", help="s3rl-train experiment (sizes)")
    p.add_argument(
        "--algo",
        default="sac_lag",
        choices=LAGRANGIAN_ALGOS,
        help="s3rl-train algo (one with a Lagrange multiplier)",
    )
    p.add_argument("--runs-dir", type=Path, default=Path("runs/lagrangian"))
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--compile", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--override", nargs="*", default=[], help="extra s3rl-train overrides")
    p.add_argument(
        "--group",
        action="store_true",
        help="train the seeds of a task and setting in one process (multi-seed trainer)",
    )
    p = sub.add_parser("plant")
    p.add_argument("--j0", type=float, default=900.0, help="cost at lambda = 0")
    p.add_argument("--k", type=float, default=486.0, help="cost removed per unit of lambda")
    p.add_argument("--noise", type=float, default=20.0, help="std of the cost per collect")
    p.add_argument("--limit", type=float, default=10.0)
    p.add_argument("--updates", type=int, default=50, help="lambda updates (1M frames: 50)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--out", type=Path, default=None, help="JSON summary")
    args = parser.parse_args(argv)
    if args.mode == "plant":
        return run_plant(args)
    run_dirs = args.run_dirs if args.mode == "summarise" else launch(args)
    return summarise(run_dirs, args.out, args.csv_dir, args.plot, getattr(args, "until", None))


if __name__ == "__main__":
    main()
