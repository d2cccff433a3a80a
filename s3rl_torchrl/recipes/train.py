"""``s3rl-train``: train S3RL, SAC-Lag or SAC on a velocity task (Hydra recipe).

    s3rl-train                                  # quick S3RL on SafetyHalfCheetahVelocity-v1
    s3rl-train algo=sac_lag task=SafetyHopperVelocity-v1 seed=20 collector.total_frames=20000
    s3rl-train -m seed=10,20 algo=s3rl,sac_lag  # a sweep
    s3rl-train resume=outputs/s3rl/.../<run>    # continue a run with its own config
    s3rl-train resume=<run> collector.total_frames=2000000   # ... with a change (printed, recorded)
    s3rl-train 'seeds=[10,20,30,40,50]'         # five seeds in one process, one batched update
    s3rl-train -m ... hydra.sweep.dir=runs/x resume=auto   # start each job, or continue it

The loop lives in :mod:`s3rl_torchrl.trainer`; this file only parses and validates the config.
A rejected config leaves no run directory behind; a run's ``train.log`` holds what it printed
(the final table, the verdict, the contrastive phases it ran and skipped) and its errors.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from s3rl_torchrl.recipes import HydraOutput, config_dir, console_to_log, quiet_known_warnings
from s3rl_torchrl.recipes.unknown_options import hint_unknown_option
from s3rl_torchrl.report.runs import final_evaluation, read_run
from s3rl_torchrl.trainer import (
    CheckpointError,
    ConfigError,
    RunInUseError,
    TrainConfig,
    TrainResult,
    register_configs,
    train,
    train_seeds,
    validate,
)
from s3rl_torchrl.trainer.resume import holds_run, resume_config

CONFIG_DIR = str(config_dir())
register_configs()

REJECTED = (ConfigError, CheckpointError, FileExistsError, RunInUseError)


def reject(err: Exception, output: HydraOutput) -> NoReturn:
    """Say why on stderr, take back the run directory Hydra made for this invocation (if it
    holds nothing else) and exit with status 2."""
    print(f"s3rl-train: {err}", file=sys.stderr)
    if not output.remove_if_untouched():  # kept: the error goes to its log too
        with console_to_log(__name__) as log:
            log.error("s3rl-train: %s", err)
    sys.exit(2)


def contrastive_summary(cfg: TrainConfig, result: TrainResult) -> str | None:
    """How many contrastive phases ran and were skipped (None: the algorithm has none)."""
    if not cfg.algo.contrastive:
        return None
    c = result.counters
    line = f"Contrastive phases: {c.contrastive_phases} ran, {c.contrastive_skipped} skipped"
    if c.contrastive_skipped:
        b = cfg.algo.contrastive_cfg.batch_size
        need = (
            f"fewer than B = {b} unsafe or 2B = {2 * b} safe transitions"
            if not cfg.algo.contrastive_cfg.graded
            else f"no label bin with 2B = {2 * b} transitions while the others hold B = {b}"
        )
        line += (
            f" (a phase is skipped while the replay buffer holds {need}; "
            'docs/representation.md, "When the contrastive phase runs")'
        )
    return line + "."


def sweep_objective(objective: str, run_dirs: Sequence[Path]) -> float | list[float]:
    """What a Hydra sweeper (e.g. Optuna's) optimises: ``objective`` (``OBJECTIVES``) of the
    final evaluation of the policy each run delivers, mean over the runs (a sweep job's seeds).

    The delivered policy is ``eval.delivery_epochs``' pick where the run made one, its last
    policy otherwise (``final_eval.json``, as ``s3rl-report`` reads it). ``reward_cost`` is
    ``[reward, cost]``, for a two-objective study (``directions: [maximize, minimize]``). NaN
    (each) while a run has no final evaluation."""
    rewards, costs = [], []
    for run_dir in run_dirs:
        run = read_run(run_dir)
        evaluation = (final_evaluation(run, "delivered") or run.final) if run.finished else None
        if evaluation is None:
            rewards, costs = [math.nan], [math.nan]
            break
        rewards.append(float(evaluation["reward_mean"]))
        costs.append(float(evaluation["cost_mean"]))
    reward, cost = sum(rewards) / len(rewards), sum(costs) / len(costs)
    return {"reward": reward, "cost": cost, "reward_cost": [reward, cost]}[objective]


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="train")
def _main(cfg: DictConfig) -> float | list[float]:
    quiet_known_warnings()  # here, not in main(): a launcher runs each job in its own process
    output = HydraOutput.current()  # before anything writes into the run directory
    # resume=auto: this command's run directory (a fixed hydra.run.dir, or a sweep's job
    # directory) is continued if it holds a run, started otherwise; the composed config must
    # then match the saved one where a resume cannot change it (the same command does).
    auto = cfg.resume == "auto"
    if auto:
        cfg.resume = None
    try:
        if auto:
            train_cfg = validate(cfg)
            if holds_run(output.dir):
                train_cfg.resume = str(output.dir)
        elif cfg.resume:
            # The run's own config; the other overrides of this command are its changes.
            changes = [o for o in HydraConfig.get().overrides.task if not o.startswith("resume=")]
            train_cfg = resume_config(cfg.resume, changes)
        else:
            train_cfg = validate(cfg)
    except (ConfigError, CheckpointError) as err:
        reject(err, output)
    with console_to_log(__name__) as log:
        log.info("s3rl-train %s", " ".join(HydraConfig.get().overrides.task))
        try:
            if train_cfg.seeds is not None:
                results = train_seeds(train_cfg, output.dir).runs
            else:
                results = [train(train_cfg, output.dir)]
        except REJECTED as err:
            reject(err, output)
        except Exception:
            log.exception("s3rl-train stopped with an error")
            raise
        for result in results:
            summary = contrastive_summary(train_cfg, result)
            if summary is not None:
                seed = f" ({result.run_dir.name})" if len(results) > 1 else ""
                print(summary.replace(":", f"{seed}:", 1))
    # An interrupted run is not a finished one: `s3rl-train ... && s3rl-report ...` stops here
    # (the status of the signal that stopped it, 128 + its number; its checkpoint is written).
    stopped = [r.exit_status for r in results if r.status == "interrupted"]
    if stopped:
        sys.exit(stopped[0])
    return sweep_objective(train_cfg.objective, [r.run_dir for r in results])


def main() -> None:
    with hint_unknown_option("s3rl-train", "train"):
        _main()


if __name__ == "__main__":
    main()
