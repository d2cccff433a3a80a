"""docs/representation.md, "When the contrastive phase runs": at the tasks' thresholds a short
run on HalfCheetah sees no unsafe step, so every phase is skipped; on Hopper every phase runs.
What the user sees of it is checked too: the line under the final table, the counters and the
``contrastive/*`` columns of the metrics rows."""

from __future__ import annotations

import math

from hydra import compose, initialize_config_dir

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.recipes.train import contrastive_summary
from s3rl_torchrl.trainer import register_configs, train, validate


def tiny(task: str):
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["experiment=tiny", f"task={task}"])
    return validate(cfg)


def contrastive_columns(row: dict) -> list[float]:
    return [v for k, v in row.items() if k.startswith("contrastive/")]


def test_halfcheetah_tiny_run_skips_every_phase(tmp_path):
    cfg = tiny("SafetyHalfCheetahVelocity-v1")
    result = train(cfg, tmp_path)
    c = result.counters
    # 125 gradient steps, a phase every update_interval = 10: 12 phases, none with data.
    expected_phases = c.grad_steps // cfg.algo.contrastive_cfg.update_interval
    assert (c.contrastive_phases, c.contrastive_skipped) == (0, expected_phases) == (0, 12)
    assert all(math.isnan(v) for row in result.history for v in contrastive_columns(row))
    assert contrastive_columns(result.history[0])  # the columns exist (NaN), as documented
    line = contrastive_summary(cfg, result)
    assert line.startswith("Contrastive phases: 0 ran, 12 skipped")
    assert "fewer than B = 8 unsafe or 2B = 16 safe" in line


def test_hopper_tiny_run_runs_every_phase(tmp_path):
    cfg = tiny("SafetyHopperVelocity-v1")
    result = train(cfg, tmp_path)
    c = result.counters
    assert (c.contrastive_phases, c.contrastive_skipped) == (12, 0)
    assert all(math.isfinite(v) for v in contrastive_columns(result.history[-1]))
    assert contrastive_summary(cfg, result) == "Contrastive phases: 12 ran, 0 skipped."
