"""Training and evaluation of every algorithm: the run's config, builders, the loop, several
seeds in one process, checkpoints and resume, evaluation.

Use it from Python without Hydra::

    from s3rl_torchrl.trainer import TrainConfig, train
    cfg = TrainConfig()
    cfg.task.name = "SafetyHopperVelocity-v1"
    result = train(cfg, "runs/hopper")
"""

from s3rl_torchrl.algorithms import (
    AlgoConfig,
    ConfigError,
    ContrastiveConfig,
    ContrastivePhase,
    PIDConfig,
)
from s3rl_torchrl.trainer.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from s3rl_torchrl.trainer.config import (
    CollectorConfig,
    DiagnosticsConfig,
    EvalConfig,
    EvalRunConfig,
    LoggerConfig,
    NetworkConfig,
    TaskConfig,
    TrainConfig,
    register_configs,
    validate,
)
from s3rl_torchrl.trainer.evaluation import EvalResult, evaluate, format_table
from s3rl_torchrl.trainer.loop import Counters, Trainer, TrainResult, compile_loss, train
from s3rl_torchrl.trainer.multiseed import MultiSeedResult, MultiSeedTrainer, train_seeds
from s3rl_torchrl.trainer.run_lock import RunInUseError

__all__ = [
    "AlgoConfig",
    "CheckpointError",
    "CollectorConfig",
    "ConfigError",
    "ContrastiveConfig",
    "ContrastivePhase",
    "Counters",
    "DiagnosticsConfig",
    "EvalConfig",
    "EvalResult",
    "EvalRunConfig",
    "LoggerConfig",
    "MultiSeedResult",
    "MultiSeedTrainer",
    "NetworkConfig",
    "PIDConfig",
    "RunInUseError",
    "TaskConfig",
    "TrainConfig",
    "TrainResult",
    "Trainer",
    "compile_loss",
    "evaluate",
    "format_table",
    "load_checkpoint",
    "register_configs",
    "save_checkpoint",
    "train",
    "train_seeds",
    "validate",
]
