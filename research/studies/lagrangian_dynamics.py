"""Launch the runs of a Lagrangian controller comparison, or run the controllers on a synthetic
plant. The runs' statistics are ``s3rl-report lagrangian`` (s3rl_torchrl/report/lagrangian.py).

Launch ``seeds x settings x tasks`` runs (one ``s3rl-train`` process each, ``--jobs`` at a time;
an existing run directory is resumed, a finished one skipped), then summarise them as
``s3rl-report lagrangian`` does::

    python research/studies/lagrangian_dynamics.py launch --tasks SafetyHalfCheetahVelocity-v1 \\
        --settings fsrl pid_ema --seeds 10 20 30 --frames 300000 --runs-dir runs/lagrangian \\
        [--out lagrangian.json] [--csv-dir DIR] [--plot lagrangian.png]

With ``--group`` the seeds of a task and setting train in ONE process (``s3rl-train
'seeds=[10,20,30]'``, the multi-seed trainer), written to
``<runs-dir>/<task>/<setting>/seed<k>/`` and resumed as a group. The runs are SAC-Lag's;
``--algo s3rl`` runs S3RL instead, into ``<runs-dir>/<task>/s3rl/<setting>/``.

Or run the controllers of those settings on the synthetic plant of the unit tests instead of a
policy (``J_{t+1} = max(0, J0 - k lambda_t + noise)``, no training, seconds)::

    python research/studies/lagrangian_dynamics.py plant [--updates 50] [--noise 20] [--k 486]

Results: docs/results.md ("Lagrangian dynamics", "Holding the limit").
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
from _report import write_report

from s3rl_torchrl.report.lagrangian import algo_dir, summarise

REPO = Path(__file__).resolve().parents[2]

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


def setting_dir(runs_dir: Path, task: str, algo: str, setting: str) -> Path:
    """Where the launcher puts a task, algo and setting's runs."""
    return (algo_dir(runs_dir, task, algo) / setting).resolve()


def _mean(values: list[float]) -> float:
    values = [v for v in values if not math.isnan(v)]
    return sum(values) / len(values) if values else math.nan


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
            # Beside the run, not in it: s3rl-train refuses a directory holding another
            # command's log (recipes/launch_checks.py).
            log = (run_dir.parent / f"{run_dir.name}.launch.log").open("a")
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
            # experiment=paper: the controllers as the paper's runs build them (the default
            # experiment, quick, has a learned multiplier of its own rate).
            overrides = ["experiment=paper", "algo=sac_lag", *BASE_OVERRIDES, *overrides]
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
    p = sub.add_parser("launch")
    p.add_argument("--out", type=Path, default=None, help="JSON summary")
    p.add_argument("--csv-dir", type=Path, default=None, help="copy metrics.csv files here")
    p.add_argument("--plot", type=Path, default=None, help="lambda and cost figure (PNG)")
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
    return summarise(launch(args), args.out, args.csv_dir, args.plot)


if __name__ == "__main__":
    main()
