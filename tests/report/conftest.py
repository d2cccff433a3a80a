"""Synthetic run directories, written the way s3rl-train writes them (config.json, metrics.csv,
final_eval.json), with numbers the tests choose."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest


def base_config(task: str, algo: str, seed: int, **changes) -> dict:
    config = {
        "task": {"name": task, "cost_limit": 10.0},
        "algo": {"name": algo, "lagrangian": "pid", "contrastive": algo == "s3rl",
                 "pid": {"kp": 0.05, "ki": 0.0005}},
        "network": {"actor_hidden": [32, 32]},
        "collector": {"total_frames": 600, "frames_per_epoch": 200},
        "eval": {"final_episodes": 4, "max_steps": 50, "random_baseline": False},
        "logger": {"backend": "csv"},
        "seed": seed,
        "threads": 1,
        "compile": False,
        "resume": None,
    }
    for dotted, value in changes.items():
        *parents, leaf = dotted.split("__")
        node = config
        for key in parents:
            node = node[key]
        node[leaf] = value
    return config


def final_evaluation(ep: dict) -> dict:
    """final_eval.json's entries (trainer.evaluation.EvalResult.to_dict) from per-episode
    rewards/costs/lengths/safe_steps."""
    return {
        "reward_mean": float(np.mean(ep["rewards"])),
        "reward_std": float(np.std(ep["rewards"])),
        "cost_mean": float(np.mean(ep["costs"])),
        "cost_std": float(np.std(ep["costs"])),
        "length_mean": float(np.mean(ep["lengths"])),
        "safe_occupancy": 100.0 * sum(ep["safe_steps"]) / sum(ep["lengths"]),
        "episodes": len(ep["rewards"]),
        "episode_rewards": ep["rewards"],
        "episode_costs": ep["costs"],
        "episode_lengths": ep["lengths"],
        "episode_safe_steps": ep["safe_steps"],
    }



def episodes(reward: float, cost: float) -> dict:
    """Two episodes of a final evaluation whose means are (reward, cost)."""
    return {"rewards": [reward - 1, reward + 1], "costs": [cost, cost],
            "lengths": [50, 50], "safe_steps": [50, 50]}

def write_run(
    path: Path,
    task: str = "SafetyHalfCheetahVelocity-v1",
    algo: str = "s3rl",
    seed: int = 1,
    episodes: dict | None = None,
    curve: dict | None = None,
    finished: bool = True,
    best_feasible: dict | None = None,
    **config_changes,
) -> Path:
    """A run directory. ``episodes``: per-episode rewards/costs/lengths/safe_steps of the final
    evaluation; ``best_feasible``: the same for the best-feasible checkpoint's evaluation
    (``final_eval.json``'s ``best_feasible`` entry, as trainer.loop writes it); ``curve``:
    metrics.csv columns (lists, one entry per epoch)."""
    path.mkdir(parents=True, exist_ok=True)
    (path / "config.json").write_text(
        json.dumps(base_config(task, algo, seed, **config_changes))
    )
    curve = curve or {
        "frames": [200, 400, 600],
        "eval/reward": [1.0 + seed, 2.0 + seed, 3.0 + seed],
        "eval/cost": [20.0, 10.0, 5.0],
        "probe/accuracy": [float("nan"), 0.7, 0.8],
        "probe/auc": [float("nan"), 0.75, 0.85],
    }
    if not finished:
        curve = {k: v[:-1] for k, v in curve.items()}
    with (path / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(list(curve))
        writer.writerows(zip(*curve.values()))
    if finished:
        final = final_evaluation(episodes or {
            "rewards": [10.0 + seed, 12.0 + seed, 11.0, 9.0],
            "costs": [0.0, 2.0, 1.0, 3.0],
            "lengths": [50, 50, 50, 50],
            "safe_steps": [50, 48, 49, 47],
        })
        if best_feasible is not None:
            final["best_feasible"] = {**final_evaluation(best_feasible), "epoch": 2}
        (path / "final_eval.json").write_text(json.dumps(final))
    return path


@pytest.fixture
def make_run():
    return write_run
