"""A search with Hydra's Optuna sweeper (``+search=lagrangian_target``, the ``search`` extra):
each trial trains in a directory of its own, and the values Optuna records are the objective
of each trial's runs, read here from their ``final_eval.json`` files by hand."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer.config import sweep_trial


def test_only_a_sweeper_that_picks_its_jobs_numbers_their_directories():
    assert sweep_trial("basic", 3) == ""
    assert sweep_trial("optuna", 3) == "_trial3"


def test_the_shipped_search_uses_the_selection_seeds():
    # Never the seeds a table reports (10, 20, 30): a search is a selection.
    search = yaml.safe_load((config_dir() / "search" / "lagrangian_target.yaml").read_text())
    assert search["seeds"] == [1, 2] and search["objective"] == "reward_cost"
    assert search["hydra"]["sweeper"]["direction"] == ["maximize", "minimize"]


@pytest.mark.slow
def test_a_two_trial_search_records_each_trials_objective(tmp_path):
    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper")
    sweep = tmp_path / "search"
    cli = str(Path(sys.executable).with_name("s3rl-train"))
    done = subprocess.run(
        [cli, "-m", "+search=lagrangian_target", "experiment=tiny", "algo=sac_lag",
         "collector.total_frames=400", "hydra.sweeper.n_trials=2", f"hydra.sweep.dir={sweep}"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "setup plugin alembic" not in done.stdout + done.stderr  # configs/train.yaml quiets it
    trials = sorted(p for p in sweep.iterdir() if p.is_dir())
    assert [p.name for p in trials] == [
        f"sac_lag_SafetyHalfCheetahVelocity-v1_seeds1-2_trial{n}" for n in (0, 1)
    ]
    # Each trial's target (from its runs' own config), and its objective by hand: the mean over
    # its two seeds of the last policy's reward and cost (tiny runs pick no delivered policy).
    by_target = {}
    for trial in trials:
        finals = [json.loads((trial / f"seed{s}" / "final_eval.json").read_text()) for s in (1, 2)]
        config = json.loads((trial / "seed1" / "config.json").read_text())
        target = config["algo"]["lagrangian_target"]
        assert 0.5 <= target <= 1.0
        by_target[target] = [statistics.fmean(f["reward_mean"] for f in finals),
                             statistics.fmean(f["cost_mean"] for f in finals)]
    assert len(by_target) == 2  # two trials, two targets
    results = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    assert results["solutions"]  # the Pareto front: trials no other beats on both objectives
    for solution in results["solutions"]:
        values = by_target[solution["params"]["algo.lagrangian_target"]]
        assert solution["values"] == pytest.approx(values)
