"""Other libraries' published results shipped as data, checked by hand against their sources,
and their section of the report."""

from __future__ import annotations

import math

import numpy as np

from s3rl_torchrl.envs.registry import TASKS
from s3rl_torchrl.report.build import build_report
from s3rl_torchrl.report.peers import load_peer_results, peer_results_for


def _one(task: str, source: str, method: str):
    (value,) = [v for v in peer_results_for(task) if v.source == source and v.method == method]
    return value


def test_values_as_published():
    # OmniSafe benchmarks/off-policy/README.md, Table 2, SACLag column (a table: exact).
    goal = _one("SafetyPointGoal1-v0", "OmniSafe", "SACLag")
    assert (goal.reward, goal.reward_std, goal.cost, goal.cost_std) == (21.45, 6.97, 19.17, 9.72)
    assert (goal.frames, goal.cost_limit, goal.approximate) == (3_000_000, 25.0, False)
    hopper = _one("SafetyHopperVelocity-v1", "OmniSafe", "SACPID")
    assert (hopper.reward, hopper.cost, hopper.frames) == (812.80, 92.23, 1_000_000)
    sac = _one("SafetyHalfCheetahVelocity-v1", "OmniSafe", "SAC (unconstrained)")
    assert math.isnan(sac.cost_limit) and sac.cost == 981.93
    # FSRL's curves (read off a plot: approximate, no std).
    ball = _one("SafetyBallRun-v0", "FSRL", "SAC-Lag")
    assert (ball.reward, ball.cost, ball.cost_limit, ball.approximate) == (390, 32, 10, True)
    assert math.isnan(ball.reward_std) and ball.frames == 500_000
    # DSRL: a trajectory within the limit, no cost of its own.
    frontier = _one("SafetyBallRun-v0", "DSRL", "best trajectory within the limit")
    assert frontier.reward == 440 and math.isnan(frontier.cost) and frontier.frames == 0


def test_every_row_names_a_registered_task_once():
    values = load_peer_results()
    assert {v.source for v in values} == {"OmniSafe", "FSRL", "DSRL"}
    assert all(v.task in TASKS for v in values)
    keys = [(v.source, v.task, v.method) for v in values]
    assert len(keys) == len(set(keys))
    # Only DSRL's rows are not training runs; only OmniSafe's are copied from tables.
    assert all((v.frames == 0) == (v.source == "DSRL") for v in values)
    assert all(v.approximate == (v.source != "OmniSafe") for v in values)


def test_report_puts_ours_beside_the_peers(tmp_path, make_run):
    episodes = {"rewards": [300.0, 310.0, 320.0, 330.0], "costs": [0.0, 2.0, 4.0, 6.0],
                "lengths": [100] * 4, "safe_steps": [100, 98, 96, 94]}
    for seed in (1, 2):
        make_run(tmp_path / "runs" / f"s3rl_seed{seed}", "SafetyBallRun-v0", "s3rl", seed,
                 episodes, collector__total_frames=1_000_000)
    text = build_report(tmp_path / "runs", tmp_path / "report", embeddings=False,
                        aggregate=False).path.read_text()
    section = text.split("## Beside other libraries' published results", 1)[1].split("\n## ")[0]
    rows = [line for line in section.splitlines() if line.startswith("| SafetyBallRun-v0 |")]
    pooled = np.array(episodes["rewards"] * 2)
    assert rows[0] == (f"| SafetyBallRun-v0 | ours | s3rl, last policy | 1M | 10 | "
                       f"{pooled.mean():.2f} ± {pooled.std():.2f} | 3.00 ± 2.24 |")
    assert "| SafetyBallRun-v0 | FSRL | SAC-Lag | 500k | 10 | ~390 | ~32 |" in rows
    assert "| SafetyBallRun-v0 | DSRL | best trajectory within the limit | – | 10 | ~440 | ≤ 10 |" in (
        rows
    )
    # Only the tasks of the report: Hopper has OmniSafe's rows but no run here.
    assert not [line for line in section.splitlines() if "SafetyHopperVelocity-v1" in line]
