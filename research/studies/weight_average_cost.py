"""What two weight averages (`eval.ema_horizons=[2000,10000]`) cost per gradient step, on the
preset's S3RL actor (SafetyHalfCheetahVelocity-v1 sizes, one thread): torch's `AveragedModel`
against `hooks/policy_average.py`'s `WeightAverage`, which computes the same average
(research/2026-12-04-delivery-rules.md).

    python research/studies/weight_average_cost.py [--steps 2000]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import torch
from hydra import compose, initialize_config_dir
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

from s3rl_torchrl.hooks.policy_average import WeightAverage
from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import Trainer, register_configs, validate

HORIZONS = (2000, 10000)


def actor() -> torch.nn.Module:
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = compose("train", overrides=["experiment=safe", "algo=s3rl", "compile=false",
                                          "task=SafetyHalfCheetahVelocity-v1"])
    return Trainer(validate(cfg), tempfile.mkdtemp() + "/run").agent.actor


def per_step(update, steps: int) -> float:
    update()  # the first update copies the weights
    start = time.perf_counter()
    for _ in range(steps):
        update()
    return 1e6 * (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    steps = parser.parse_args().steps
    torch.set_num_threads(1)
    policy = actor()
    print(f"actor: {sum(p.numel() for p in policy.parameters())} parameters")
    torch_averages = [AveragedModel(policy, multi_avg_fn=get_ema_multi_avg_fn(1 - 1 / h))
                      for h in HORIZONS]
    ours = [WeightAverage(policy, 1 - 1 / h) for h in HORIZONS]
    for name, averages, call in (
        ("AveragedModel.update_parameters", torch_averages, "update_parameters"),
        ("WeightAverage.update", ours, "update"),
    ):
        def update(averages=averages, call=call):
            for average in averages:
                getattr(average, call)(policy)

        print(f"{name}, {len(HORIZONS)} averages: {per_step(update, steps):.1f} us per step")


if __name__ == "__main__":
    main()
