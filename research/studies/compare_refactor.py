"""Does a refactor change what a run computes? Seeded runs of every algorithm family, made with
one version of the code and then another, compared file by file.

    # in a checkout of the code BEFORE the change (PYTHONPATH picks the tree):
    PYTHONPATH=<before tree> python research/studies/compare_refactor.py run --out <dir>/before \
        [--critic-eval vmap]
    # in the checkout AFTER the change:
    PYTHONPATH=<after tree> python research/studies/compare_refactor.py run --out <dir>/after \
        [--extra diagnostics.probes=true]
    python research/studies/compare_refactor.py compare <dir>/before <dir>/after \
        [--out research/results/<name>.json]

``run`` trains each of :data:`RUNS` (``s3rl-train`` with ``hydra.run.dir=<out>/<run>``), one
fresh process per run, with the code that ``PYTHONPATH`` selects. ``--critic-eval`` makes every
``SACLagLoss`` of the run use that critic evaluation (for a version of the loss that still had
several, so that the reference is made with the evaluation the other version keeps). With it,
``StackedSACLag``'s template loss also gets back the batch size of each critic's parameters
inside its ``vmap`` over seeds (what the later version does), without which the ``"vmap"``
evaluation cannot run under that ``vmap``; it changes no number. ``--extra`` appends overrides
to every run (e.g. a switch that the other version spells differently).

``compare`` holds each run's ``metrics.csv`` (every cell as text, the timing column
``eval/seconds`` aside) and ``final_eval.json`` (as text) of the two directories against each
other, for every seed of a ``seeds=[...]`` run, and writes which are byte-identical.

    python research/studies/compare_refactor.py speed --trees <before tree> <after tree> \
        [--rounds 2] [--frames 20000] [--out research/results/<name>.json]

``speed`` measures ``benchmarks/train_throughput.py``'s quantity, the compiled S3RL recipe at
the paper's settings on HalfCheetah (env steps per second after the first epoch, evaluation
aside), for each tree in turn, ``--rounds`` times, interleaved (a fresh process each), and also
the process CPU time over the same window (evaluation included): with other jobs on the cores,
CPU time is what the code costs.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
from _report import write_report

STUDIES = Path(__file__).resolve().parent

# experiment=tiny sizes (32x32 networks, 2 envs, 100-frame batches, 200-frame epochs) for 2000
# frames: 10 epochs, ~450 gradient steps. Hopper's young policies do cost (the contrastive phase
# and the graded probe then have both kinds of states); HalfCheetah's do not.
HOPPER = "task=SafetyHopperVelocity-v1"
TINY = ("experiment=tiny", "logger=none", "collector.total_frames=2000")
RUNS: dict[str, tuple[str, ...]] = {
    "s3rl": ("algo=s3rl", HOPPER),
    "s3rl_cost_to_go": ("algo=s3rl", HOPPER, "algo.contrastive_cfg.label=cost_to_go"),
    "sac_lag_fsrl_order": ("algo=sac_lag", HOPPER, "algo.update_order=fsrl"),
    "sac_lag_sound_learned_step": (
        "algo=sac_lag",
        HOPPER,
        "critic=sound",
        "algo.lagrangian=learned",
        "algo.lagrangian_cadence=step",
    ),
    "sac": ("algo=sac", "task=SafetyHalfCheetahVelocity-v1"),
    "ddpg_lag": ("algo=ddpg_lag", HOPPER),
    "s3rl_ddpg_lag": ("algo=s3rl_ddpg_lag", HOPPER),
    "ppo_lag": ("algo=ppo_lag", HOPPER),
    "s3rl_ppo_lag": ("algo=s3rl_ppo_lag", HOPPER),
    "ppo": ("algo=ppo", HOPPER),
    "sac_lag_seeds": ("algo=sac_lag", HOPPER, "seeds=[1,2]"),
    "s3rl_compiled": ("algo=s3rl", HOPPER, "compile=true"),
    "sac_lag_seeds_compiled": ("algo=sac_lag", HOPPER, "seeds=[1,2]", "compile=true"),
}
TIMING_COLUMNS = ("eval/seconds",)
COMPARED_FILES = ("metrics.csv", "final_eval.json")

# What the child process runs: the recipe, optionally with every SACLagLoss forced to one
# critic evaluation (a keyword of the loss in the versions that had several).
CHILD = """
import functools, sys
studies, critic_eval, argv = sys.argv[1], sys.argv[2], sys.argv[3:]
if critic_eval:
    from s3rl_torchrl.objectives import sac_lag
    init = sac_lag.SACLagLoss.__init__

    @functools.wraps(init)
    def forced(self, *args, **kwargs):
        kwargs["critic_eval"] = critic_eval
        init(self, *args, **kwargs)

    sac_lag.SACLagLoss.__init__ = forced

    sys.path.insert(0, studies)
    from _before_issue37 import give_template_batch_sizes, stacked_module

    give_template_batch_sizes(stacked_module())
from s3rl_torchrl.recipes.train import main
sys.argv = ["s3rl-train", *argv]
main()
"""


def run(out: Path, critic_eval: str | None, extra: list[str], only: list[str] | None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    for name, overrides in RUNS.items():
        if only and name not in only:
            continue
        run_dir = (out / name).resolve()
        if run_dir.exists():
            raise SystemExit(f"{run_dir} exists: remove it or choose another --out")
        argv = [*TINY, *overrides, *extra, f"hydra.run.dir={run_dir}"]
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-c", CHILD, str(STUDIES), critic_eval or "", *argv],
            check=True,
            env={**os.environ, "PYTHONHASHSEED": "0"},
            # Not in a checkout: `python -c` puts the working directory first on sys.path, where
            # a checkout's package would shadow the one PYTHONPATH names.
            cwd=out,
        )
        timings[name] = round(time.perf_counter() - start, 1)
        print(f"{name}: {timings[name]} s", flush=True)
    # One record per run (a later `run --only ...` into the same directory adds its runs).
    record_file = out / "runs.json"
    record = json.loads(record_file.read_text()) if record_file.is_file() else {"runs": {}}
    for name, seconds in timings.items():
        record["runs"][name] = {
            "command": " ".join(sys.argv),
            "pythonpath": os.environ.get("PYTHONPATH", ""),
            "critic_eval": critic_eval,
            "overrides": [*TINY, *RUNS[name], *extra],
            "seconds": seconds,
        }
    record_file.write_text(json.dumps(record, indent=2) + "\n")


SPEED_CHILD = """
import json, sys, tempfile, time
sys.path.insert(0, sys.argv[1])
from _report import recipe_config
from s3rl_torchrl.trainer import Trainer
task, frames = sys.argv[2], int(sys.argv[3])
epoch = recipe_config("experiment=paper", f"task={task}").collector.frames_per_epoch
frames = -(-frames // epoch) * epoch
cfg = recipe_config("experiment=paper", f"task={task}", f"collector.total_frames={epoch + frames}",
                    "compile=true", "threads=1")
marks = []
def on_epoch_end(trainer, row):
    marks.append((row["frames"], time.perf_counter(), time.process_time(), row["eval/seconds"]))
with tempfile.TemporaryDirectory() as run_dir:
    trainer = Trainer(cfg, run_dir, on_epoch_end=on_epoch_end)
    trainer.cfg.eval.final_episodes = 1
    trainer.run()
(f0, t0, c0, _), (f1, t1, c1, _) = marks[0], marks[-1]
wall = t1 - t0 - sum(m[3] for m in marks[1:])
print(json.dumps({"frames_measured": f1 - f0, "wall_seconds_without_eval": round(wall, 2),
                  "env_steps_per_s": round((f1 - f0) / wall, 1),
                  "cpu_seconds": round(c1 - c0, 2),
                  "env_steps_per_cpu_s": round((f1 - f0) / (c1 - c0), 1),
                  "gradient_steps": trainer.counters.grad_steps}))
"""


def speed(trees: list[Path], rounds: int, frames: int, task: str, out: Path | None) -> None:
    bench = str(_paths.BENCHMARKS)
    rows = []
    for round_index in range(rounds):
        for tree in trees:
            load = os.getloadavg()[0]
            done = subprocess.run(
                [sys.executable, "-c", SPEED_CHILD, bench, task, str(frames)],
                check=True,
                capture_output=True,
                text=True,
                env={**os.environ, "PYTHONPATH": str(tree)},
                cwd=tempfile.gettempdir(),
            )
            row = {"tree": str(tree), "round": round_index, "load_before": round(load, 2)}
            row |= json.loads(done.stdout.strip().splitlines()[-1])
            row["load_after"] = round(os.getloadavg()[0], 2)
            print(json.dumps(row), flush=True)
            rows.append(row)
    if out is not None:
        write_report(out, {"task": task, "rows": rows})


def _run_files(run_dir: Path) -> dict[str, Path]:
    """Every compared file of a run (``seed<k>/`` sub-directories of a group included)."""
    files = {}
    for path in sorted(run_dir.rglob("*")):
        if path.name in COMPARED_FILES and "checkpoints" not in path.parts:
            files[str(path.relative_to(run_dir))] = path
    return files


def _metrics_cells(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    kept = [i for i, column in enumerate(header) if column not in TIMING_COLUMNS]
    return [header[i] for i in kept], [[row[i] for i in kept] for row in body]


def _difference(a: Path, b: Path) -> str | None:
    """None when the two files are the same (metrics: timing column aside), else the first
    difference."""
    if a.suffix == ".json":
        if a.read_bytes() == b.read_bytes():
            return None
        ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
        keys = sorted(k for k in set(ja) | set(jb) if ja.get(k) != jb.get(k))
        return f"final_eval.json differs in {keys}"
    (ha, ra), (hb, rb) = _metrics_cells(a), _metrics_cells(b)
    if ha != hb:
        return f"columns differ: {sorted(set(ha) ^ set(hb)) or 'same set, other order'}"
    if len(ra) != len(rb):
        return f"{len(ra)} rows against {len(rb)}"
    for index, (row_a, row_b) in enumerate(zip(ra, rb, strict=True)):
        for column, x, y in zip(ha, row_a, row_b, strict=True):
            if x != y:
                return f"row {index + 1}, {column}: {x} against {y}"
    return None


def compare(before: Path, after: Path, out: Path | None) -> bool:
    results = {}
    for run_dir in sorted(p for p in before.iterdir() if p.is_dir()):
        files_a, files_b = _run_files(run_dir), _run_files(after / run_dir.name)
        differences = {}
        if "final_eval.json" not in {Path(name).name for name in files_a}:
            differences["run"] = "did not finish before"
        for name in sorted(set(files_a) | set(files_b)):
            if name not in files_a or name not in files_b:
                differences[name] = "missing in " + ("after" if name in files_a else "before")
                continue
            difference = _difference(files_a[name], files_b[name])
            if difference is not None:
                differences[name] = difference
        results[run_dir.name] = {
            "files": sorted(files_a),
            "identical": not differences,
            "differences": differences,
        }
        print(f"{run_dir.name}: {'identical' if not differences else differences}")
    identical = all(r["identical"] for r in results.values())
    if out is not None:
        setup = {
            side: json.loads((path / "runs.json").read_text())
            for side, path in (("before", before), ("after", after))
            if (path / "runs.json").is_file()
        }
        write_report(
            out,
            {
                "what": "metrics.csv (eval/seconds aside) and final_eval.json, text-identical",
                "all_identical": identical,
                "setup": setup,
                "runs": results,
            },
        )
    return identical


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    run_parser = commands.add_parser("run", help="train every run with the code on PYTHONPATH")
    run_parser.add_argument("--out", type=Path, required=True)
    run_parser.add_argument("--critic-eval", default=None)
    run_parser.add_argument("--extra", nargs="*", default=[])
    run_parser.add_argument("--only", nargs="*", default=None, choices=list(RUNS))
    compare_parser = commands.add_parser("compare", help="compare two directories of runs")
    compare_parser.add_argument("before", type=Path)
    compare_parser.add_argument("after", type=Path)
    compare_parser.add_argument("--out", type=Path)
    speed_parser = commands.add_parser("speed", help="train_throughput's measure, per tree")
    speed_parser.add_argument("--trees", type=Path, nargs="+", required=True)
    speed_parser.add_argument("--rounds", type=int, default=2)
    speed_parser.add_argument("--frames", type=int, default=20_000)
    speed_parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    speed_parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.command == "run":
        run(args.out, args.critic_eval, args.extra, args.only)
    elif args.command == "speed":
        speed(args.trees, args.rounds, args.frames, args.task, args.out)
    elif not compare(args.before, args.after, args.out):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
