"""The critic diagnostics hook (hooks/critics.py): on by default for the SAC family only,
switched off by ``diagnostics.critics=false``, and free of any effect on training."""

from __future__ import annotations

import csv

import pytest

from s3rl_torchrl.hooks import CriticDiagnostics
from s3rl_torchrl.trainer import Trainer


def _columns(run_dir) -> set[str]:
    with open(run_dir / "metrics.csv") as file:
        return set(next(csv.reader(file)))


def _rows(run_dir) -> list[dict]:
    with open(run_dir / "metrics.csv") as file:
        return list(csv.DictReader(file))


@pytest.mark.parametrize(
    "algo, logged", [("s3rl", True), ("sac", True), ("ddpg_lag", False), ("ppo_lag", False)]
)
def test_on_for_the_sac_family_only(algo, logged, tiny_config, tmp_path):
    trainer = Trainer(tiny_config(f"algo={algo}", "collector.total_frames=400"), tmp_path)
    assert CriticDiagnostics.supports(trainer.agent.loss) == logged
    assert ("critic_diagnostics" in trainer.state_dict()["hooks"]) == logged
    trainer.run()
    columns = {c for c in _columns(tmp_path) if c.startswith(("critic/", "grad/"))}
    expected = {f"critic/{s}_{n}" for s in ("reward", "cost") for n in ("q", "return", "error",
                                                                           "rmse")}
    expected |= {"grad/entropy", "grad/reward", "grad/cost"}
    assert columns == (expected if logged else set())


def test_switched_off_it_changes_nothing_else(tiny_config, tmp_path):
    overrides = ("algo=sac_lag", "task=SafetyHopperVelocity-v1", "collector.total_frames=600")
    on = Trainer(tiny_config(*overrides), tmp_path / "on")
    on.run()
    off = Trainer(tiny_config(*overrides, "diagnostics.critics=false"), tmp_path / "off")
    assert off.state_dict()["hooks"] == {}
    off.run()
    for a, b in zip(_rows(tmp_path / "on"), _rows(tmp_path / "off"), strict=True):
        diagnostics = {k for k in a if k.startswith(("critic/", "grad/"))}
        assert diagnostics and not diagnostics & set(b)
        for key in (*diagnostics, "eval/seconds"):
            a.pop(key)
        b.pop("eval/seconds")
        assert a == b
    # The episodes it keeps are its state in the checkpoint.
    assert on.state_dict()["hooks"]["critic_diagnostics"]["episodes"]
