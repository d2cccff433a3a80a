"""``s3rl-train``'s line about the contrastive phases under the final table."""

from __future__ import annotations

from pathlib import Path

from s3rl_torchrl.recipes.train import contrastive_summary
from s3rl_torchrl.trainer import Counters, TrainConfig, TrainResult


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
