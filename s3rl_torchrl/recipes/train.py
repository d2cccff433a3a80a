"""``s3rl-train``: train S3RL, SAC-Lag or SAC on a velocity task (Hydra recipe).

    s3rl-train                                  # quick S3RL on SafetyHalfCheetahVelocity-v1
    s3rl-train algo=sac_lag task=SafetyHopperVelocity-v1 seed=20 collector.total_frames=20000
    s3rl-train -m seed=10,20 algo=s3rl,sac_lag  # a sweep
    s3rl-train resume=outputs/s3rl/.../<run>    # continue an interrupted run
    s3rl-train 'seeds=[10,20,30,40,50]'         # five seeds in one process, one batched update

The loop lives in :mod:`s3rl_torchrl.trainer`; this file only parses and validates the config.
"""

from __future__ import annotations

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from s3rl_torchrl.recipes import config_dir, quiet_known_warnings
from s3rl_torchrl.trainer import (
    CheckpointError,
    ConfigError,
    register_configs,
    train,
    train_seeds,
    validate,
)

CONFIG_DIR = str(config_dir())
register_configs()


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="train")
def _main(cfg: DictConfig) -> float:
    try:
        train_cfg = validate(cfg)
        output_dir = HydraConfig.get().runtime.output_dir
        if train_cfg.seeds is not None:
            results = train_seeds(train_cfg, output_dir).runs
        else:
            results = [train(train_cfg, output_dir)]
    except (ConfigError, CheckpointError, FileExistsError) as err:
        print(f"s3rl-train: {err}", file=sys.stderr)
        sys.exit(2)
    # The return value is what Hydra sweepers (e.g. Optuna) optimise (the mean over seeds).
    rewards = [r.final_eval.reward_mean for r in results if r.final_eval is not None]
    return sum(rewards) / len(rewards) if len(rewards) == len(results) else float("nan")


def main() -> None:
    quiet_known_warnings()
    _main()


if __name__ == "__main__":
    main()
