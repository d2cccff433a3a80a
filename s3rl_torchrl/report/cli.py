"""``s3rl-report``: the paper's Table 1 and Figures 2-4 from a directory of runs."""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence

from s3rl_torchrl.report.runs import ReportError, export_runs


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
    )
    parser.add_argument("runs", help="a run, a Hydra multirun/sweep dir or an outputs dir")
    parser.add_argument("--out", default=None, help="report directory (default: RUNS/report)")
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


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    from s3rl_torchrl.report.build import build_report, export_embedding_panels

    argv = sys.argv[1:] if argv is None else list(argv)
    if args.export_runs is not None:
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
