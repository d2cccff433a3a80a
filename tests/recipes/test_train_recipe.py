"""``s3rl-train``: the line about the contrastive phases under the final table, what it returns
to a sweeper, and resume=auto across a sweep."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from s3rl_torchrl.recipes.train import contrastive_summary, sweep_objective
from s3rl_torchrl.trainer import ConfigError, Counters, TrainConfig, TrainResult, train, validate
from tests.report.conftest import episodes, write_run


def result(ran: int, skipped: int) -> TrainResult:
    counters = Counters(contrastive_phases=ran, contrastive_skipped=skipped)
    return TrainResult(Path("run"), "finished", counters)


def test_no_line_without_a_contrastive_phase():
    cfg = TrainConfig()
    cfg.algo.contrastive = False  # sac_lag, sac, ddpg_lag, ...
    assert contrastive_summary(cfg, result(0, 0)) is None


def test_skips_are_explained_with_the_runs_batch_size():
    cfg = TrainConfig()
    cfg.algo.contrastive_cfg.batch_size = 64
    line = contrastive_summary(cfg, result(3, 14))
    assert line.startswith("Contrastive phases: 3 ran, 14 skipped (a phase is skipped while ")
    assert "fewer than B = 64 unsafe or 2B = 128 safe transitions" in line
    assert '"When the contrastive phase runs"' in line
    cfg.algo.contrastive_cfg.label = "cost_to_go"
    assert "no label bin with 2B = 128 transitions while the others hold B = 64" in (
        contrastive_summary(cfg, result(0, 1))
    )
    assert contrastive_summary(cfg, result(5, 0)) == "Contrastive phases: 5 ran, 0 skipped."


def test_a_sweeper_gets_the_delivered_policys_evaluation_mean_over_seeds(tmp_path):
    # Seed 1 delivered its last policy (no pick); seed 2 its pick (eval.delivery_epochs),
    # whose evaluation is final_eval.json's `delivered`, not the last policy's 20 / 4.
    last = write_run(tmp_path / "seed1", seed=1, episodes=episodes(10, 2))
    picked = write_run(tmp_path / "seed2", seed=2, episodes=episodes(20, 4),
                       eval__delivery_epochs=10)
    final = json.loads((picked / "final_eval.json").read_text())
    final["delivered"] = {"reward_mean": 30.0, "cost_mean": 6.0, "epoch": 3}
    (picked / "final_eval.json").write_text(json.dumps(final))
    runs = [last, picked]
    assert sweep_objective("reward", runs) == pytest.approx((10 + 30) / 2)
    assert sweep_objective("cost", runs) == pytest.approx((2 + 6) / 2)
    assert sweep_objective("reward_cost", runs) == pytest.approx([20.0, 4.0])
    # A run that was to pick but kept no candidate delivered its last policy.
    del final["delivered"]
    (picked / "final_eval.json").write_text(json.dumps(final))
    assert sweep_objective("reward", runs) == pytest.approx((10 + 20) / 2)
    # A run without a final evaluation (interrupted): nothing to optimise yet.
    unfinished = write_run(tmp_path / "seed3", seed=3, finished=False)
    assert math.isnan(sweep_objective("reward", [last, unfinished]))
    assert all(math.isnan(v) for v in sweep_objective("reward_cost", [unfinished, last]))


def test_the_objective_of_a_trained_run_and_a_bad_choice(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=200", "objective=cost")
    result = train(cfg, tmp_path / "run")
    saved = json.loads((tmp_path / "run" / "final_eval.json").read_text())
    assert sweep_objective(cfg.objective, [result.run_dir]) == saved["cost_mean"]
    cfg.objective = "safety"
    with pytest.raises(ConfigError, match="'objective'.*reward, cost, reward_cost"):
        validate(cfg)


def _train(*args: str, cwd: Path):
    import subprocess
    import sys

    cli = str(Path(sys.executable).with_name("s3rl-train"))
    return subprocess.run([cli, *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_resume_auto_starts_then_continues_each_job_of_a_sweep(tmp_path):
    # The evidence workflow: the same multirun command, run again after an interruption,
    # continues each job in its own directory (here: both jobs had finished, so their final
    # evaluations stand and nothing is retrained).
    sweep = tmp_path / "sweep"
    args = ["-m", "experiment=tiny", "algo=sac", "seed=1,2", "collector.total_frames=200",
            f"hydra.sweep.dir={sweep}", "hydra.sweep.subdir=seed${seed}", "resume=auto"]
    first = _train(*args, cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    saved = {s: (sweep / f"seed{s}" / "final_eval.json").read_text() for s in (1, 2)}
    again = _train(*args, cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("not recomputed") == 2
    assert {s: (sweep / f"seed{s}" / "final_eval.json").read_text() for s in (1, 2)} == saved


def test_resume_alone_refuses_a_new_seed_or_a_config_group(tmp_path):
    run = tmp_path / "run"
    done = _train("experiment=tiny", "algo=sac", "collector.total_frames=200",
                  f"hydra.run.dir={run}", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    seed = _train(f"resume={run}", "seed=3", cwd=tmp_path)
    assert seed.returncode == 2 and "seed: the run has 10, the override gives 3" in seed.stderr
    group = _train(f"resume={run}", "experiment=safe", cwd=tmp_path)
    assert group.returncode == 2 and "experiment would replace a whole config group" in group.stderr
    assert not (run / "resumes").exists() or not any((run / "resumes").iterdir())
