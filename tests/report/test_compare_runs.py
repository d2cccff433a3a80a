"""s3rl-report compare-runs (report/compare_runs.py): largest relative differences of two
hand-made runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from s3rl_torchrl.report.cli import main


def fake_run(root: Path, rewards: list[float], seconds: list[float], final: float) -> Path:
    root.mkdir()
    lines = ["frames,eval/reward,eval/seconds,probe/auc"]
    lines += [f"{10 * (i + 1)},{r},{s},nan" for i, (r, s) in enumerate(zip(rewards, seconds))]
    (root / "metrics.csv").write_text("\n".join(lines) + "\n")
    (root / "final_eval.json").write_text(
        json.dumps({"reward_mean": final, "cost_mean": 2.0, "safe_occupancy": 90.0})
    )
    return root


def test_differences_by_hand_and_timings_left_out(tmp_path, capsys):
    a = fake_run(tmp_path / "a", [100.0, 200.0], [1.0, 1.0], 50.0)
    b = fake_run(tmp_path / "b", [100.0, 210.0], [9.0, 9.0], 55.0)
    argv = ["compare-runs", str(a), str(b), "--out", str(tmp_path / "out.json")]
    assert main(argv) == 0
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["command"] == "s3rl-report " + " ".join(argv)
    assert out["max_relative_difference_by_column"] == {
        "frames": 0.0, "eval/reward": pytest.approx(0.05), "probe/auc": 0.0  # NaN == NaN
    }
    assert out["relative_difference_final_eval"] == {
        "reward_mean": pytest.approx(0.1), "cost_mean": 0.0, "safe_occupancy": 0.0
    }
    printed = json.loads(capsys.readouterr().out.splitlines()[0])
    assert printed["max_relative_difference_metrics_csv"] == pytest.approx(0.05)


def test_runs_of_different_lengths_are_refused(tmp_path, capsys):
    a = fake_run(tmp_path / "a", [1.0, 2.0], [1.0, 1.0], 1.0)
    b = fake_run(tmp_path / "b", [1.0], [1.0], 1.0)
    assert main(["compare-runs", str(a), str(b)]) == 2
    assert "different numbers of epochs: 2 and 1" in capsys.readouterr().err
