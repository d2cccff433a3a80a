"""benchmarks/harness.py and run.py: every standing benchmark runs at its quick size (seconds,
eager, tiny sizes; the numbers measure nothing and nothing about them is asserted) and gives
its rows; run.py puts them in one table and one JSON file. No timing is asserted here: speed
targets are the benchmarks' business (docs/benchmarks.md)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import harness  # noqa: E402

# The ones that train (a few hundred frames of the recipe) take several seconds.
TRAINING = {"train_throughput", "compute_floor", "multiseed"}


def test_the_registry_holds_the_standing_set():
    assert list(harness.STANDING) == [
        "env_throughput", "sampler", "loss_step", "train_throughput", "compute_floor",
        "multiseed",
    ]
    assert all(benchmark.what for benchmark in harness.STANDING.values())


@pytest.mark.parametrize("name", [
    pytest.param(name, marks=pytest.mark.slow) if name in TRAINING else name
    for name in harness.STANDING
])
def test_every_standing_benchmark_gives_its_rows_at_the_quick_size(name):
    rows = harness.run_benchmark(name, "quick")
    assert rows
    for row in rows:
        assert row["benchmark"] == name
        assert isinstance(row["case"], str) and row["case"]
        assert isinstance(row["unit"], str) and row["unit"]
        assert isinstance(row["value"], float) and math.isfinite(row["value"]), row
        json.dumps(row)  # goes into the results file as it is
    assert len({row["case"] for row in rows}) == len(rows)


def test_an_unknown_size_is_refused():
    with pytest.raises(ValueError, match="size"):
        harness.run_benchmark("sampler", "huge")


@pytest.mark.slow
def test_run_prints_one_table_and_writes_its_rows(tmp_path):
    out = tmp_path / "standing.json"
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / "run.py"), "sampler", "--quick", "--out", str(out)],
        capture_output=True, text=True, check=True,
    )
    lines = done.stdout.splitlines()
    table = lines[lines.index("| benchmark | case | value | unit |"):]
    saved = json.loads(out.read_text())
    assert saved["size"] == "quick" and set(saved["benchmarks"]) == {"sampler"}
    assert "error" not in saved["benchmarks"]["sampler"]
    assert {row["benchmark"] for row in saved["rows"]} == {"sampler"}
    assert len(table) == 2 + len(saved["rows"])  # the table comes last
    assert saved["command"].startswith("python ") and "run.py sampler --quick" in saved["command"]


def test_run_refuses_an_unknown_benchmark():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "run.py"), "nope", "--quick"],
                          capture_output=True, text=True)
    assert done.returncode == 2 and "unknown benchmark" in done.stderr


def test_every_study_imports():
    """The one-off studies are not run here (each is minutes of measurement), but what they
    import from the package must still exist."""
    import importlib

    studies = BENCHMARKS.parent / "research" / "studies"  # the one-off studies' home
    sys.path.insert(0, str(studies))
    names = sorted(p.stem for p in studies.glob("*.py") if not p.stem.startswith("_"))
    assert "lagrangian_dynamics" in names and len(names) >= 14
    for name in names:
        importlib.import_module(name)
