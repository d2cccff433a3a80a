"""What every benchmark script shares: the config of a measured recipe run, interleaved timing
rounds, and its results as JSON with the command that made them, by default in the archive
of the day (``benchmarks/results/archive/<date>/<name>.json``)."""

from __future__ import annotations

import datetime
import json
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

RESULTS = Path(__file__).resolve().parent / "results"

# What a measured recipe run leaves out: logging, checkpoints, long evaluations.
MEASURED_RUN = [
    "eval.episodes=1",
    "eval.random_baseline=false",
    "logger=none",
    "logger.progress_bar=false",
    "save_interval=1000",
]


def recipe_config(*overrides: str):
    """The validated ``s3rl-train`` config of ``overrides`` on top of :data:`MEASURED_RUN`
    (as the recipe composes it: ``configs/`` and its schema)."""
    from hydra import compose, initialize_config_dir

    from s3rl_torchrl.recipes import config_dir
    from s3rl_torchrl.trainer import register_configs, validate

    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return validate(compose(config_name="train", overrides=[*MEASURED_RUN, *overrides]))


def archive_path(name: str) -> Path:
    """Where a script writes its results unless ``--out`` says otherwise:
    ``benchmarks/results/archive/<today>/<name>.json`` (the harness's tables go to
    ``benchmarks/results/standing/``, run.py)."""
    return RESULTS / "archive" / datetime.date.today().isoformat() / f"{name}.json"


def command_line() -> str:
    """The command as typed (``python benchmarks/<script>.py ...``)."""
    return "python " + " ".join(sys.argv)


def machine() -> dict[str, str]:
    return {"platform": platform.platform(), "torch": torch.__version__}


def interleaved_rounds(
    cases: dict[str, Callable[[], object]],
    calls: int,
    rounds: int,
    warmup: int,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, list[float]]:
    """Microseconds per call of every case, one value per round. Each round times every case in
    turn, so that load from other processes hits them all alike. ``clock``: wall time by
    default; ``time.process_time`` counts this process's CPU time only."""
    for fn in cases.values():
        for _ in range(warmup):
            fn()
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, fn in cases.items():
            start = clock()
            for _ in range(calls):
                fn()
            times[name].append((clock() - start) / calls * 1e6)
    return times


def write_report(path: Path, report: dict) -> None:
    """Write ``report`` as JSON, with the command and machine unless it gives its own."""
    report = {"command": command_line(), "machine": machine(), **report}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {path}")
