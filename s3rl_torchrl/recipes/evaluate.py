"""``s3rl-eval``: evaluate a checkpoint with deterministic actions (Hydra recipe).

    s3rl-eval checkpoint=outputs/s3rl/<task>/seed10/<time>     # the run's own eval settings
    s3rl-eval checkpoint=<run dir> episodes=10 max_steps=1000    # given values win
    s3rl-eval checkpoint=<run dir> video=true                    # also writes episode.mp4

The video (one episode, unsafe steps framed in red, running cost and reward on every frame)
renders on a headless machine as is: the package picks MuJoCo's offscreen backend
(``s3rl_torchrl/_render_backend.py``); docs/video.md.

``episodes``, ``num_envs``, ``seed`` and ``max_steps`` default to the run's own evaluation
settings, read from the checkpoint (``trainer.evaluate_checkpoint.eval_settings``), so the
numbers measure what the run's final table measured. Prints the settings used, the result
table and the path of ``eval.json`` (in Hydra's output directory).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import hydra
from hydra.core.config_store import ConfigStore
from hydra.core.hydra_config import HydraConfig
from omegaconf import MISSING, DictConfig, OmegaConf

from s3rl_torchrl._render_backend import RenderBackendError
from s3rl_torchrl.recipes import HydraOutput, config_dir, console_to_log, quiet_known_warnings
from s3rl_torchrl.recipes.unknown_options import hint_unknown_option
from s3rl_torchrl.trainer import (
    CheckpointError,
    ConfigError,
    format_table,
    register_configs,
    validate,
)
from s3rl_torchrl.trainer.config import check_seed
from s3rl_torchrl.trainer.evaluate_checkpoint import eval_settings, evaluate_policy, load_policy

CONFIG_DIR = str(config_dir())
EXAMPLE = "s3rl-eval checkpoint=outputs/s3rl/SafetyHalfCheetahVelocity-v1/seed10/<time>"
MISSING_CHECKPOINT = (
    f"missing checkpoint=<run to evaluate> (a run directory, a checkpoint directory or a "
    f"state.pt file), e.g. {EXAMPLE}"
)


@dataclass
class EvalCommandConfig:
    """``s3rl-eval``'s options (``configs/evaluate.yaml``). ``None``: the run's own setting
    (:func:`~s3rl_torchrl.trainer.evaluate_checkpoint.eval_settings`)."""

    checkpoint: str = MISSING  # a run directory, a checkpoint directory or a state.pt file
    episodes: int | None = None  # None: the run's eval.final_episodes
    num_envs: int | None = None  # None: the run's eval.num_envs
    seed: int | None = None  # None: the run's test-env seed
    max_steps: int | None = None  # None: the run's eval.max_steps
    video: bool = False
    video_path: str | None = None

    def check(self) -> None:
        if not self.checkpoint.strip():
            raise ConfigError(MISSING_CHECKPOINT)
        for name in ("episodes", "num_envs", "max_steps"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ConfigError(
                    f"Invalid value {value!r} for '{name}': must be in [1, inf), or null for "
                    "the run's own."
                )
        if self.seed is not None:
            check_seed("seed", self.seed)


register_configs()
ConfigStore.instance().store(name="eval_command_schema", node=EvalCommandConfig)


def reject(err: Exception | str, output: HydraOutput) -> NoReturn:
    """One line on stderr, no output directory left behind, exit status 2."""
    print(f"s3rl-eval: {err}", file=sys.stderr)
    if not output.remove_if_untouched():  # kept: the error goes to its log too
        with console_to_log(__name__) as log:
            log.error("s3rl-eval: %s", err)
    sys.exit(2)


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="evaluate")
def _main(cfg: DictConfig) -> float:
    quiet_known_warnings()  # here, not in main(): a launcher runs each job in its own process
    output = HydraOutput.current()  # before anything writes into the output directory
    if OmegaConf.is_missing(cfg, "checkpoint"):
        reject(MISSING_CHECKPOINT, output)
    try:
        command: EvalCommandConfig = validate(cfg, EvalCommandConfig)
    except ConfigError as err:
        reject(err, output)
    with console_to_log(__name__) as log:
        log.info("s3rl-eval %s", " ".join(HydraConfig.get().overrides.task))
        try:
            actor, train_cfg = load_policy(command.checkpoint)
            settings = eval_settings(
                train_cfg,
                episodes=command.episodes,
                num_envs=command.num_envs,
                seed=command.seed,
                max_steps=command.max_steps,
            )
            print(f"Evaluating {command.checkpoint} with {settings.describe()}.")
            video_path = None
            if command.video:
                video_path = Path(command.video_path or output.dir / "episode.mp4")
            result = evaluate_policy(actor, train_cfg, settings, video_path)
        except (CheckpointError, RenderBackendError) as err:
            reject(err, output)
        except Exception:
            log.exception("s3rl-eval stopped with an error")
            raise
        saved = result.to_dict() | {
            "checkpoint": command.checkpoint,
            "settings": settings.to_dict(),
        }
        eval_json = output.dir / "eval.json"
        eval_json.write_text(json.dumps(saved, indent=2) + "\n")
        label = f"{train_cfg.algo.name} {train_cfg.task.name} seed {train_cfg.seed}"
        title = f"Evaluation of {command.checkpoint}: {result.episodes} deterministic episodes"
        print("\n" + format_table({label: result}, title=title) + "\n")
        print(f"Results: {eval_json}")
        if video_path is not None:
            print(f"Video: {video_path}")
    return result.reward_mean


def main() -> None:
    with hint_unknown_option("s3rl-eval", "evaluate"):
        _main()


if __name__ == "__main__":
    main()
