"""benchmarks/compare_runs.py: largest relative differences of two hand-made runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "compare_runs.py"


def fake_run(root: Path, rewards: list[float], seconds: list[float], final: float) -> Path:
    root.mkdir()
    lines = ["frames,eval/reward,eval/seconds,probe/auc"]
    lines += [f"{10 * (i + 1)},{r},{s},nan" for i, (r, s) in enumerate(zip(rewards, seconds))]
    (root / "metrics.csv").write_text("\n".join(lines) + "\n")
    (root / "final_eval.json").write_text(
        json.dumps({"reward_mean": final, "cost_mean": 2.0, "safe_occupancy": 90.0})
    )
    return root


def compare(a: Path, b: Path, out: Path) -> dict:
    subprocess.run([sys.executable, SCRIPT, a, b, "--out", out], check=True,
                   capture_output=True)
    return json.loads(out.read_text())


def test_differences_by_hand_and_timings_left_out(tmp_path):
    a = fake_run(tmp_path / "a", [100.0, 200.0], [1.0, 1.0], 50.0)
    b = fake_run(tmp_path / "b", [100.0, 210.0], [9.0, 9.0], 55.0)
    out = compare(a, b, tmp_path / "out.json")
    assert out["max_relative_difference_by_column"] == {
        "frames": 0.0, "eval/reward": pytest.approx(0.05), "probe/auc": 0.0  # NaN == NaN
    }
    assert out["relative_difference_final_eval"] == {
        "reward_mean": pytest.approx(0.1), "cost_mean": 0.0, "safe_occupancy": 0.0
    }


def test_runs_of_different_lengths_are_refused(tmp_path):
    a = fake_run(tmp_path / "a", [1.0, 2.0], [1.0, 1.0], 1.0)
    b = fake_run(tmp_path / "b", [1.0], [1.0], 1.0)
    result = subprocess.run([sys.executable, SCRIPT, a, b], capture_output=True, text=True)
    assert result.returncode != 0 and "different numbers of epochs" in result.stderr
