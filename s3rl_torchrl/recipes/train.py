"""``s3rl-train``: train S3RL, SAC-Lag or SAC on a velocity task (Hydra recipe).

    s3rl-train                                  # quick S3RL on SafetyHalfCheetahVelocity-v1
    s3rl-train algo=sac_lag task=SafetyHopperVelocity-v1 seed=20 collector.total_frames=20000
    s3rl-train -m seed=10,20 algo=s3rl,sac_lag  # a sweep
    s3rl-train resume=outputs/s3rl/.../<run>    # continue an interrupted run

The loop lives in :mod:`s3rl_torchrl.trainer`; this file only parses and validates the config.
"""

from __future__ import annotations

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import CheckpointError, ConfigError, register_configs, train, validate

CONFIG_DIR = str(config_dir())
register_configs()


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="train")
def _main(cfg: DictConfig) -> float:
    try:
        train_cfg = validate(cfg)
        result = train(train_cfg, HydraConfig.get().runtime.output_dir)
    except (ConfigError, CheckpointError, FileExistsError) as err:
        print(f"s3rl-train: {err}", file=sys.stderr)
        sys.exit(2)
    # The return value is what Hydra sweepers (e.g. Optuna) optimise.
    return result.final_eval.reward_mean if result.final_eval is not None else float("nan")


def main() -> None:
    _main()


if __name__ == "__main__":
    main()
