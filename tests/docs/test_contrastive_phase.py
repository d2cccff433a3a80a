"""docs/representation.md, "When the contrastive phase runs": at the tasks' thresholds a short
run on HalfCheetah sees no unsafe step, so every phase is skipped; on Hopper every phase runs.
What the user sees of it is checked too: the line under the final table, the counters and the
``contrastive/*`` columns of the metrics rows."""

from __future__ import annotations

import math

import pytest
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
    # 125 gradient steps, a phase every update_interval = 10 at the start of each interval
    # (after steps 11, 21, ..., 121): 12 phases, none with data.
    assert c.grad_steps == 125 and cfg.algo.contrastive_cfg.update_interval == 10
    assert (c.contrastive_phases, c.contrastive_skipped) == (0, 12)
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


@pytest.mark.parametrize("phase_at, steps", [("start", 11), ("end", 10)])
def test_a_phase_runs_after_the_step_phase_at_names(phase_at, steps, tmp_path, monkeypatch):
    # Which gradient step each phase of a tiny Hopper run follows, counted from the
    # algorithm's own update calls: 11, 21, ... (start) or 10, 20, ... (end), T = 10.
    from s3rl_torchrl.algorithms.contrastive import ContrastivePhase
    from s3rl_torchrl.trainer.loop import Trainer

    updates, after = [], []
    update, run = Trainer._update, ContrastivePhase.run

    def counted_update(self, batch):
        updates.append(None)
        return update(self, batch)

    def recorded_run(self):
        after.append(len(updates))
        return run(self)

    monkeypatch.setattr(Trainer, "_update", counted_update)
    monkeypatch.setattr(ContrastivePhase, "run", recorded_run)
    cfg = tiny("SafetyHopperVelocity-v1")
    cfg.algo.contrastive_cfg.phase_at = phase_at
    result = train(cfg, tmp_path)
    assert result.counters.grad_steps == len(updates) == 125
    assert after == list(range(steps, 125, 10))
    assert result.counters.contrastive_phases == 12
