"""Issue 60's evidence, the shipped sweep `configs/sweep/table1_v2.yaml` (96 runs), as one
resumable queue that copies each run into version control as it finishes; `--sweep` runs another
shipped sweep the same way (issue 63's `reproduction` into results/reproduction).

    python research/delivered_policy/evidence.py --out runs/table1_v2 --export results/table1_v2
    python research/delivered_policy/evidence.py --sweep reproduction

Each job is the sweep's own (the same overrides, one `s3rl-train` run per job in
`<out>/<algo>_<task>/seed<N>`, the sweep's subdir), two at a time, in the sweep's order. A finished
run is copied into `--export` (config.json, metrics.csv, final_eval.json, what `make report`
reads) and a run copied already is skipped, so the queue continues on a machine where `runs/`
and its checkpoints are gone; an unfinished run resumes from its checkpoint (`resume=auto`).
The queue itself is selection.py's (`run_queue`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml
from hydra import compose, initialize_config_dir

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.recipes.launch_checks import sweep_overrides as expand_sweep
from s3rl_torchrl.trainer import register_configs

sys.path.insert(0, str(Path(__file__).resolve().parent))  # research/ is not a package
from selection import run_queue  # noqa: E402

SWEEP = "table1_v2"


def sweep_overrides(name: str = SWEEP) -> list[list[str]]:
    """Each job's overrides, in the order Hydra's basic sweeper launches them."""
    params = yaml.safe_load((config_dir() / "sweep" / f"{name}.yaml").read_text())
    params = params["hydra"]["sweeper"]["params"]
    return expand_sweep(f"{key}={value}" for key, value in params.items())


def jobs(out: Path, name: str = SWEEP):
    """``(run_dir, overrides)`` per job: the sweep's subdir under ``out``. Hydra's global
    config directory is held until the generator is exhausted or closed."""
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        for overrides in sweep_overrides(name):
            cfg = compose("train", overrides=[f"+sweep={name}", *overrides],
                          return_hydra_config=True)
            run_dir = out / cfg.hydra.sweep.subdir
            yield run_dir, [*overrides, f"hydra.run.dir={run_dir}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    shipped = sorted(p.stem for p in (config_dir() / "sweep").glob("*.yaml"))
    parser.add_argument("--sweep", choices=shipped, default=SWEEP,
                        help=f"a shipped sweep, configs/sweep/<name>.yaml (default: {SWEEP})")
    parser.add_argument("--out", type=Path, help="the runs (default: runs/<sweep>)")
    parser.add_argument("--export", type=Path,
                        help="copy each finished run here and skip the runs copied already "
                        "(default: results/<sweep>)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    out = args.out or Path("runs") / args.sweep
    export = args.export or Path("results") / args.sweep
    run_queue(list(jobs(out, args.sweep)), out, export, args.workers)


if __name__ == "__main__":
    main()
