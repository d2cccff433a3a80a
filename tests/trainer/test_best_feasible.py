"""The best-feasible checkpoint (FSRL's ``perf_is_better``) and the final table's verdict."""

from __future__ import annotations

import json
import math

import pytest
import torch

from s3rl_torchrl.trainer import train
from s3rl_torchrl.trainer.evaluate_checkpoint import evaluate_checkpoint
from s3rl_torchrl.trainer.evaluation import BestFeasible, constraint_verdict
from s3rl_torchrl.trainer.metrics import read_metrics


def fsrl_best(epochs, limit):
    """FSRL's base_trainer.perf_is_better, as it reads there, over (reward, cost) per epoch:
    the index of the epoch whose checkpoint model_best.pt holds at the end."""
    best_rew, best_cost, best = -math.inf, math.inf, None
    for i, (rew, cost) in enumerate(epochs):
        if best_cost > limit:
            if cost <= limit or rew > best_rew:
                best_rew, best_cost, best = rew, cost, i
        elif cost <= limit and rew > best_rew:
            best_rew, best_cost, best = rew, cost, i
    return best


def test_best_feasible_rule_by_hand():
    # limit 10. Epoch 1: infeasible, first: best. Epoch 2: infeasible, higher reward: best.
    # Epoch 3: feasible, lower reward: best (feasible beats infeasible). Epoch 4: infeasible,
    # much higher reward: not best any more. Epoch 5: feasible, higher: best. Epoch 6: feasible,
    # lower: not. Epoch 7: cost exactly at the limit and higher: best (<= limit is feasible).
    epochs = [(100, 50), (300, 40), (200, 5), (900, 80), (250, 9), (240, 0), (260, 10)]
    best = BestFeasible()
    became = [best.update(r, c, 10.0, i + 1, 1000 * (i + 1)) for i, (r, c) in enumerate(epochs)]
    assert became == [True, True, True, False, True, False, True]
    assert (best.reward, best.cost, best.epoch, best.frames) == (260, 10, 7, 7000)
    assert fsrl_best(epochs, 10.0) == 6


def test_verdict_names_the_cost_against_the_limit():
    assert constraint_verdict(4.0, 10.0, 40_000) == "Within the cost limit: mean cost 4.00 <= d = 10."
    short = constraint_verdict(19.4, 10.0, 40_000)
    assert short.startswith("Over the cost limit: mean cost 19.40 > d = 10 after 40000 frames.")
    assert "has not converged" in short
    long = constraint_verdict(19.4, 10.0, 1_000_000)
    assert "does not keep the constraint" in long and "converged" not in long


@pytest.mark.slow
def test_run_keeps_and_evaluates_the_best_feasible_checkpoint(tiny_config, tmp_path, capsys):
    # Hopper with a limit of 1: some epochs are within it, some not (random-ish early policy).
    cfg = tiny_config(
        "algo=sac_lag", "task=SafetyHopperVelocity-v1", "task.cost_limit=1",
        "collector.total_frames=1000",
    )
    train(cfg, tmp_path)
    rows = read_metrics(tmp_path)
    epochs = [(float(r["eval/reward"]), float(r["eval/cost"])) for r in rows]
    chosen = fsrl_best(epochs, cfg.task.cost_limit)

    final = json.loads((tmp_path / "final_eval.json").read_text())
    best = final["best_feasible"]
    assert best["epoch"] == chosen + 1 and best["frames"] == int(rows[chosen]["frames"])
    assert (best["reward"], best["cost"]) == pytest.approx(epochs[chosen])
    assert best["feasible"] == (epochs[chosen][1] <= cfg.task.cost_limit)
    assert best["episodes"] == cfg.eval.final_episodes == len(best["episode_rewards"])
    # The checkpoint holds the weights of that epoch (its counters say so), s3rl-eval loads it.
    best_dir = tmp_path / "checkpoints" / "best"
    state = torch.load(best_dir / "state.pt", weights_only=True)
    assert state["counters"]["frames"] == best["frames"]
    assert "replay_buffer" not in {p.name for p in best_dir.iterdir()}
    result, _ = evaluate_checkpoint(best_dir, episodes=1, num_envs=1, max_steps=10)
    assert result.episodes == 1
    out = capsys.readouterr().out
    assert f"checkpoint (epoch {best['epoch']}, {best['frames']} frames; FSRL's rule)" in out
    assert "cost limit" in out.split("Run directory")[0].splitlines()[-2]
