"""``s3rl-report``: the paper's Table 1 and Figures 2-4 from a directory of runs, and two
analyses of runs as subcommands:

    s3rl-report RUNS [--out DIR] ...                  the report (report.md, figures)
    s3rl-report lagrangian RUN_DIR... [--out ...]     the Lagrange multiplier's dynamics
    s3rl-report compare-runs RUN_A RUN_B [--out ...]  do two runs give the same metrics?
    s3rl-report before-after --before OLD... --after NEW...   two presets, paired per seed
    s3rl-report gap --setting NAME=DIR[,DIR...]...    one algo against another, per preset

A first argument naming a subcommand selects it; anything else is the report's ``RUNS`` (a
directory that happens to be called ``lagrangian`` is written ``./lagrangian``).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from s3rl_torchrl.report.runs import PROTOCOLS, ReportError, export_runs


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _non_negative(text: str) -> int:
    value = int(text)
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2**32), got {text}")
    return value


def _pair(text: str) -> tuple[str, str]:
    first, sep, second = text.partition(":")
    if not sep or not first or not second:
        raise argparse.ArgumentTypeError(f"expected two algos as A:B, got {text!r}")
    return first, second


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="s3rl-report",
        description=(
            "Find every run (a directory with config.json and metrics.csv) below RUNS, group "
            "them by task and algo, and write report.md with Table 1, the S3RL-vs-baseline "
            "tests, the paper's numbers, the aggregate over tasks (rliable) and Figures 2-4 "
            "(PNG and SVG)."
        ),
        epilog=(
            "Subcommands (each with --help): 's3rl-report lagrangian RUN_DIR...' summarises "
            "how the Lagrange multiplier and the cost behave over training; 's3rl-report "
            "compare-runs RUN_A RUN_B' gives the largest relative difference of two runs' "
            "metrics; 's3rl-report before-after --before OLD... --after NEW...' pairs two "
            "presets' runs per seed; 's3rl-report gap --setting NAME=DIR[,DIR...]...' puts one "
            "algo against another on the same tasks under several presets."
        ),
    )
    parser.add_argument("runs", nargs="+",
                        help="a run, a Hydra multirun/sweep dir or an outputs dir; several "
                             "are reported as one (e.g. two exported results trees)")
    parser.add_argument("--out", default=None,
                        help="report directory (default: RUNS/report, the first RUNS')")
    parser.add_argument("--reference", default="s3rl",
                        help="the algo compared with every other one (default: s3rl)")
    parser.add_argument("--compare", action="append", default=[], metavar="A:B",
                        type=_pair,
                        help="also test algo A minus algo B (e.g. s3rl_ddpg_lag:ddpg_lag); A "
                             "and B may also be group labels as the tables print them, for "
                             "groups split by --group-by (e.g. 's3rl (algo.contrastive_cfg."
                             "label=cost_to_go):s3rl (algo.contrastive_cfg.label=binary)'); "
                             "repeatable")
    parser.add_argument("--group-by", action="append", default=[], metavar="KEY",
                        help="a config key (dotted, e.g. algo.pid.kp) that splits the runs of "
                             "one task and algo into separate groups; repeatable")
    parser.add_argument("--no-embeddings", action="store_true",
                        help="skip Figure 4 and the probe table (no checkpoint rollouts); with "
                             "--export-runs: store no Figure-4 panels")
    parser.add_argument("--embedding-episodes", type=_positive, default=2,
                        help="evaluation env copies rolled out per checkpoint (default: 2)")
    parser.add_argument("--tsne-states", type=_positive, default=1000,
                        help="at most this many states per t-SNE panel (default: 1000; "
                             "t-SNE time grows faster than linearly)")
    parser.add_argument("--aggregate", action=argparse.BooleanOptionalAction, default=None,
                        help="the aggregate over tasks and seeds (rliable: interquartile means, "
                             "probability of improvement, share within the limit, performance "
                             "profiles, with stratified-bootstrap intervals); default: included "
                             "when rliable is installed (pip install \"s3rl-torchrl[report]\"), "
                             "else the report says so; --aggregate: required; --no-aggregate: "
                             "left out")
    parser.add_argument("--aggregate-reps", type=_positive, default=2000,
                        help="bootstrap resamples per aggregate estimate (default: 2000)")
    parser.add_argument("--aggregate-seed", type=_non_negative, default=0,
                        help="seed of the aggregate's bootstrap (default: 0; the same seed "
                             "rebuilds the same intervals)")
    parser.add_argument("--export-runs", default=None, metavar="DEST",
                        help="copy config.json, metrics.csv and final_eval.json of every run "
                             "to DEST (same layout; no checkpoints; copies of runs gone from "
                             "RUNS are removed), store each group's Figure-4 "
                             "panel (t-SNE coordinates and probe, drawn from its checkpoint) "
                             "beside its copy, and exit: a small tree to keep in version "
                             "control, from which `s3rl-report DEST` rebuilds the report")
    return parser.parse_args(argv)


def lagrangian_main(argv: Sequence[str]) -> int:
    """``s3rl-report lagrangian``: :func:`s3rl_torchrl.report.lagrangian.summarise`."""
    parser = argparse.ArgumentParser(
        prog="s3rl-report lagrangian",
        description=(
            "How the Lagrange multiplier and the cost behave over training: per run, statistics "
            "over the second half of training (cost over the limit, |delta lambda|, lambda, "
            "reward and cost, the training cost's lag-1 autocorrelation, the final evaluation), "
            "then their mean and std over seeds per task, algo and controller setting; printed "
            "as a table."
        ),
    )
    parser.add_argument("run_dirs", nargs="+", type=Path, metavar="RUN_DIR",
                        help="s3rl-train run directories (those without metrics.csv are skipped)")
    parser.add_argument("--out", type=Path, default=None, help="JSON summary")
    parser.add_argument("--csv-dir", type=Path, default=None, help="copy metrics.csv files here")
    parser.add_argument("--plot", type=Path, default=None, help="lambda and cost figure (PNG)")
    parser.add_argument("--until", type=int, default=None, metavar="FRAMES",
                        help="read the runs as if they had stopped at this many frames")
    args = parser.parse_args(argv)
    from s3rl_torchrl.report.lagrangian import summarise

    summarise(args.run_dirs, args.out, args.csv_dir, args.plot, args.until,
              command=shlex.join(["s3rl-report", "lagrangian", *argv]))
    return 0


def compare_runs_main(argv: Sequence[str]) -> int:
    """``s3rl-report compare-runs``: :func:`s3rl_torchrl.report.compare_runs.compare_runs`."""
    parser = argparse.ArgumentParser(
        prog="s3rl-report compare-runs",
        description=(
            "Do two runs give the same metrics? The largest relative difference per metrics.csv "
            "column (timings left out) and of the final evaluation, e.g. of a seeded run before "
            "and after a speed-up."
        ),
    )
    parser.add_argument("a", type=Path, metavar="RUN_A")
    parser.add_argument("b", type=Path, metavar="RUN_B")
    parser.add_argument("--out", type=Path, default=None, help="JSON summary")
    args = parser.parse_args(argv)
    from s3rl_torchrl.report.compare_runs import compare_runs
    from s3rl_torchrl.report.records import write_json

    try:
        summary = compare_runs(args.a, args.b)
    except (ReportError, OSError) as err:
        print(f"s3rl-report compare-runs: error: {err}", file=sys.stderr)
        return 2
    print(json.dumps({k: v for k, v in summary.items()
                      if k != "max_relative_difference_by_column"}))
    if args.out is not None:
        write_json(args.out, summary, shlex.join(["s3rl-report", "compare-runs", *argv]))
    return 0


def _task_target(text: str) -> tuple[str, tuple[float, float]]:
    task, _, bars = text.partition("=")
    reward, sep, cost = bars.partition(",")
    try:
        if not task or not sep:
            raise ValueError
        return task, (float(reward), float(cost))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected TASK=REWARD,COST (e.g. SafetyPointGoal1-v0=20,25), got {text!r}"
        ) from None


def _algo_count(text: str) -> tuple[str, int]:
    algo, sep, count = text.partition("=")
    if not algo or not sep or not count.isdigit():
        raise argparse.ArgumentTypeError(f"expected ALGO=RUNS (e.g. s3rl=46), got {text!r}")
    return algo, int(count)


def before_after_main(argv: Sequence[str]) -> int:
    """``s3rl-report before-after``: :func:`s3rl_torchrl.report.before_after.before_after`."""
    parser = argparse.ArgumentParser(
        prog="s3rl-report before-after",
        description=(
            "The same tasks, algos and seeds under two presets (two sets of result trees), "
            "paired per seed: mean reward and cost per task and algo before and after, the runs "
            "within the limit, paired t-tests, and the targets a new preset has to meet."
        ),
    )
    parser.add_argument("--before", nargs="+", required=True, metavar="DIR",
                        help="the old preset's result trees")
    parser.add_argument("--after", nargs="+", required=True, metavar="DIR",
                        help="the new preset's result trees")
    parser.add_argument("--protocol", default="last", choices=tuple(PROTOCOLS),
                        help="which final evaluation (default: last, the policy at the end; "
                             "best_feasible: FSRL's checkpoint; delivered: eval.delivery_epochs' "
                             "pick)")
    parser.add_argument("--within", action="append", default=[], type=_algo_count,
                        metavar="ALGO=RUNS",
                        help="runs of ALGO that must be within the limit after (default: all)")
    parser.add_argument("--reward-kept", type=float, default=0.85,
                        help="share of the old reward to keep where the old cost was within the "
                             "limit (default: 0.85)")
    parser.add_argument("--task-target", action="append", default=[], type=_task_target,
                        metavar="TASK=REWARD,COST",
                        help="least mean reward and most mean cost a task must reach after")
    parser.add_argument("--moving-share", type=float, default=0.1,
                        help="a run whose final reward is at most this share of its best "
                             "evaluation reward in training has stopped (default: 0.1)")
    parser.add_argument("--out", type=Path, required=True, help="markdown page")
    parser.add_argument("--json", type=Path, default=None, help="the same as JSON")
    args = parser.parse_args(argv)
    from dataclasses import asdict

    from s3rl_torchrl.report.before_after import before_after, write_markdown
    from s3rl_torchrl.report.records import write_json

    command = shlex.join(["s3rl-report", "before-after", *argv])
    try:
        result = before_after(
            args.before, args.after, args.protocol, within_target=dict(args.within),
            reward_kept=args.reward_kept, task_targets=dict(args.task_target),
            moving_share=args.moving_share,
        )
    except ReportError as err:
        print(f"s3rl-report before-after: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {write_markdown(result, args.out, command)}")
    if args.json is not None:
        rows = [{**asdict(row), "within_before": row.within("before"),
                 "within_after": row.within("after")} for row in result.rows]
        write_json(args.json, {"protocol": result.protocol, "rows": rows,
                               "targets": [asdict(t) for t in result.targets],
                               "unpaired": result.unpaired,
                               "misses": [{**asdict(m), "reason": m.reason, "cause": m.cause}
                                          for m in result.misses],
                               "stops": [asdict(s) for s in result.stops]}, command)
    return 0


def _setting(text: str) -> tuple[str, list[str]]:
    name, sep, trees = text.partition("=")
    paths = [t for t in trees.split(",") if t]
    if not name or not sep or not paths:
        raise argparse.ArgumentTypeError(
            f"expected NAME=DIR[,DIR...] (e.g. paper=results/reproduction), got {text!r}")
    return name, paths


def gap_main(argv: Sequence[str]) -> int:
    """``s3rl-report gap``: :func:`s3rl_torchrl.report.gap.gap`."""
    parser = argparse.ArgumentParser(
        prog="s3rl-report gap",
        description=(
            "One algo against another on the tasks of the first setting, under every setting "
            "(a preset's result trees): per task the mean cost and reward of each, their "
            "paired difference and the paper's, and per setting rliable's probability of "
            "improvement over the tasks all settings have."
        ),
    )
    parser.add_argument("--setting", action="append", required=True, type=_setting,
                        metavar="NAME=DIR[,DIR...]",
                        help="a preset's name and result trees; the first one's tasks are read")
    parser.add_argument("--reference", default="s3rl", help="default: s3rl")
    parser.add_argument("--baseline", default="sac_lag", help="default: sac_lag")
    parser.add_argument("--protocol", default="last", choices=tuple(PROTOCOLS),
                        help="which final evaluation (default: last)")
    parser.add_argument("--reps", type=_positive, default=2000,
                        help="bootstrap resamples (default: 2000)")
    parser.add_argument("--seed", type=_non_negative, default=0, help="bootstrap seed")
    parser.add_argument("--out", type=Path, required=True, help="markdown page")
    parser.add_argument("--json", type=Path, default=None, help="the same as JSON")
    args = parser.parse_args(argv)
    names = [name for name, _ in args.setting]
    if len(set(names)) < len(names):
        parser.error(f"each --setting needs its own name, got {', '.join(names)}")
    from dataclasses import asdict

    from s3rl_torchrl.report.gap import gap, write_markdown
    from s3rl_torchrl.report.records import write_json

    command = shlex.join(["s3rl-report", "gap", *argv])
    try:
        result = gap(dict(args.setting), args.reference, args.baseline, args.protocol,
                     reps=args.reps, seed=args.seed)
    except ReportError as err:
        print(f"s3rl-report gap: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {write_markdown(result, args.out, command)}")
    if args.json is not None:
        rows = [{"task": row.task, "setting": row.setting, "cost_limit": row.cost_limit,
                 "seeds": {algo: {str(s): {"reward": v[0], "cost": v[1]}
                                  for s, v in sorted(by_seed.items())}
                           for algo, by_seed in row.seeds.items()},
                 "reward_difference": asdict(row.reward_test),
                 "cost_difference": asdict(row.cost_test),
                 "paper_cost_difference": result.paper_difference(row.task, "cost"),
                 "paper_reward_difference": result.paper_difference(row.task, "reward")}
                for (_, _), row in sorted(result.rows.items())]
        write_json(args.json, {"reference": result.reference, "baseline": result.baseline,
                               "protocol": result.protocol, "settings": result.settings,
                               "rows": rows, "shared_tasks": result.shared,
                               "answers": [asdict(a) for a in result.answers],
                               "missing": result.missing}, command)
    return 0


SUBCOMMANDS: dict[str, Callable[[Sequence[str]], int]] = {
    "lagrangian": lagrangian_main,
    "compare-runs": compare_runs_main,
    "before-after": before_after_main,
    "gap": gap_main,
}


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in SUBCOMMANDS:
        return SUBCOMMANDS[argv[0]](argv[1:])
    args = parse_args(argv)
    from s3rl_torchrl.recipes import quiet_known_warnings
    from s3rl_torchrl.report.build import build_report, export_embedding_panels

    # The embedding panels build each task's envs: MuJoCo's settotalmass warning, once per
    # env built, says nothing a reader of the report can act on (recipes/__init__.py).
    quiet_known_warnings()

    if args.export_runs is not None:
        if len(args.runs) > 1:
            print("s3rl-report: error: --export-runs copies one RUNS directory (its layout "
                  f"below DEST mirrors it); got {len(args.runs)}: {' '.join(args.runs)}.",
                  file=sys.stderr)
            return 2
        args.runs = args.runs[0]
        try:
            export = export_runs(args.runs, args.export_runs)
            panels = [] if args.no_embeddings else export_embedding_panels(
                args.runs, args.export_runs, args.embedding_episodes, args.tsne_states)
        except ReportError as err:
            print(f"s3rl-report: error: {err}", file=sys.stderr)
            return 2
        print(f"Copied the results of {len(export.copied)} runs to {args.export_runs}"
              + (f" and Figure 4's panels of {len(panels)} of them" if panels else "")
              + (f"; removed {len(export.removed)} run copies no longer in {args.runs}: "
                 + ", ".join(str(p) for p in export.removed) if export.removed else ""))
        return 0
    try:
        report = build_report(
            args.runs,
            args.out,
            reference=args.reference,
            group_by=args.group_by,
            pairs=args.compare,
            embeddings=not args.no_embeddings,
            embedding_episodes=args.embedding_episodes,
            tsne_states=args.tsne_states,
            command=shlex.join(["s3rl-report", *argv]),
            aggregate=args.aggregate,
            aggregate_reps=args.aggregate_reps,
            aggregate_seed=args.aggregate_seed,
        )
    except ReportError as err:
        print(f"s3rl-report: error: {err}", file=sys.stderr)
        return 2
    for note in report.notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"Wrote {report.path} and {len(report.figures)} figure files in {report.path.parent}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
