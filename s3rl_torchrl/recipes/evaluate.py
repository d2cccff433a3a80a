"""``s3rl-eval``: evaluate a checkpoint with deterministic actions (Hydra recipe).

    s3rl-eval checkpoint=outputs/s3rl/<task>/seed10/<time> episodes=10
    s3rl-eval checkpoint=<run dir> video=true            # also writes episode.mp4

Prints the result table and writes ``eval.json`` to Hydra's output directory.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from s3rl_torchrl.recipes import config_dir, quiet_known_warnings
from s3rl_torchrl.trainer import (
    CheckpointError,
    ConfigError,
    EvalRunConfig,
    format_table,
    register_configs,
    validate,
)
from s3rl_torchrl.trainer.evaluate_checkpoint import evaluate_checkpoint

CONFIG_DIR = str(config_dir())
register_configs()


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="evaluate")
def _main(cfg: DictConfig) -> float:
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        eval_cfg: EvalRunConfig = validate(cfg, EvalRunConfig)
        video_path = None
        if eval_cfg.video:
            video_path = eval_cfg.video_path or out_dir / "episode.mp4"
        result, train_cfg = evaluate_checkpoint(
            eval_cfg.checkpoint,
            episodes=eval_cfg.episodes,
            num_envs=eval_cfg.num_envs,
            seed=eval_cfg.seed,
            max_steps=eval_cfg.max_steps,
            video_path=video_path,
        )
    except (ConfigError, CheckpointError) as err:
        print(f"s3rl-eval: {err}", file=sys.stderr)
        sys.exit(2)
    result.save(out_dir / "eval.json")
    label = f"{train_cfg.algo.name} {train_cfg.task.name} seed {train_cfg.seed}"
    print("\n" + format_table({label: result}, title=f"Evaluation of {eval_cfg.checkpoint}"))
    if video_path is not None:
        print(f"Video: {video_path}")
    return result.reward_mean


def main() -> None:
    quiet_known_warnings()
    _main()


if __name__ == "__main__":
    main()
