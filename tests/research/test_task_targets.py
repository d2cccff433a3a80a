"""research/delivered_policy/task_targets.py (SafetyAntCircle's own target, issue 60): its jobs
are the preset's runs on seeds 1 and 2 but for the target, its verdict follows the note's rule on
hand-made runs, and the committed table is what it reads from the exported runs."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import pytest

from tests.conftest import compose_train
from tests.research.test_delivered_selection import ROOT, _script

RESULTS = ROOT / "research" / "results" / "task_targets"


@pytest.fixture(scope="module")
def targets():
    return _script("task_targets")


def test_the_jobs_are_the_presets_runs_on_the_selection_seeds_but_for_the_target(targets, tmp_path):
    from s3rl_torchrl.trainer import validate

    jobs = list(targets.jobs(tmp_path))
    assert [run_dir.relative_to(tmp_path).as_posix() for run_dir, _ in jobs] == [
        f"antcircle_target1/{algo}_SafetyAntCircle-v0/seed{seed}"
        for seed in (1, 2) for algo in ("sac_lag", "s3rl")
    ]
    for run_dir, overrides in jobs:
        assert f"hydra.run.dir={run_dir}" in overrides
        cfg = validate(compose_train(*[o for o in overrides if not o.startswith("hydra.")]))
        preset = validate(compose_train("experiment=safe", "task=SafetyAntCircle-v0",
                                        f"algo={cfg.algo.name}", f"seed={cfg.seed}"))
        assert cfg.seed in (1, 2)  # never a reported seed (10, 20, 30)
        assert cfg.collector.total_frames == 1_000_000
        assert preset.algo.lagrangian_target == 0.7 and cfg.algo.lagrangian_target == 1.0
        # Everything else is the preset's, its delivered pick included.
        assert cfg.eval == preset.eval and cfg.eval.delivery_epochs == 10
        assert cfg.task == preset.task and cfg.network == preset.network
        assert replace(cfg.algo, lagrangian_target=0.7) == preset.algo


def _run(algo, reward, cost, limit=10.0):
    return SimpleNamespace(algo=algo, task="SafetyAntCircle-v0", cost_limit=limit,
                           final={"delivered": {"reward_mean": reward, "cost_mean": cost}})


def test_the_verdict_follows_the_rule_by_hand(targets):
    reference = {("sac_lag", "SafetyAntCircle-v0"): 80.0, ("s3rl", "SafetyAntCircle-v0"): 60.0}
    # Medians of the picks' reward over the reference: sac_lag (40 + 120) / 2 / 80 = 1.0;
    # s3rl (30 + 72) / 2 / 60 = 0.85, at the line.
    runs = [_run("sac_lag", 40.0, 0.0), _run("sac_lag", 120.0, 10.0),
            _run("s3rl", 30.0, 3.0), _run("s3rl", 72.0, 9.9)]
    assert targets.verdict("c", runs, reference) == (
        "The rule's verdict on c: it enters (4 of 4 picks within the limit; reward kept: "
        "sac_lag 1.00, s3rl 0.85).")
    over = [*runs[:3], _run("s3rl", 72.0, 10.1)]
    assert "it misses (1 of 4 picks over the limit;" in targets.verdict("c", over, reference)
    short = [*runs[:3], _run("s3rl", 71.0, 0.0)]  # (30 + 71) / 2 / 60 = 0.84
    assert targets.verdict("c", short, reference) == (
        "The rule's verdict on c: it misses (reward kept below 0.85 for s3rl; reward kept: "
        "sac_lag 1.00, s3rl 0.84).")
    # A part of the round decides only a miss: a pick over the limit, never a short reward.
    assert "not yet (3 of 4 runs finished)" in targets.verdict("c", runs[:3], reference)
    assert "not yet (1 of 4 runs finished)" in targets.verdict("c", short[3:], reference)
    assert targets.verdict("c", [runs[0], over[3]], reference) == (
        "The rule's verdict on c: it misses (1 of the 2 finished picks over the limit; every one "
        "of the 4 must be within, so the other 2 runs cannot change it).")


def test_the_committed_table_is_the_exported_runs(targets):
    committed = (ROOT / "research" / "delivered_policy" / "task_targets.md").read_text()
    assert committed == targets.summarise(RESULTS)
