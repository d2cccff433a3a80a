"""Every logger backend writes the run's metrics where the docs say (no server needed)."""

from __future__ import annotations

import pytest

from s3rl_torchrl.trainer import ConfigError, train, validate
from s3rl_torchrl.trainer import config as config_module

ARGS = ("algo=sac", "collector.total_frames=200")


def test_tensorboard(tiny_config, tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    train(tiny_config(*ARGS, "logger=tensorboard"), tmp_path)
    (events,) = tmp_path.glob("logs/*/events.out.tfevents.*")
    acc = EventAccumulator(str(events.parent))
    acc.Reload()
    assert "eval/reward" in acc.Tags()["scalars"]
    assert [e.step for e in acc.Scalars("eval/reward")] == [200]


def test_wandb_offline(tiny_config, tmp_path):
    train(tiny_config(*ARGS, "logger=wandb"), tmp_path)
    runs = list(tmp_path.glob("logs/wandb/offline-run-*/run-*.wandb"))
    assert len(runs) == 1 and runs[0].stat().st_size > 0


def test_mlflow_file_store(tiny_config, tmp_path):
    train(tiny_config(*ARGS, "logger=mlflow"), tmp_path)
    (metric,) = tmp_path.glob("logs/mlruns/*/*/metrics/eval/reward")
    step_values = [line.split() for line in metric.read_text().splitlines()]
    assert len(step_values) == 1 and step_values[0][2] == "200"  # "timestamp value step"


@pytest.mark.parametrize("backend", ["wandb", "mlflow"])
def test_runs_in_one_process_each_log_their_own_run(tiny_config, tmp_path, backend):
    # Hydra's basic launcher runs a -m sweep's jobs one after another in one process; W&B and
    # MLflow keep one active run per process, which a finished job must end.
    first, second = tmp_path / "first", tmp_path / "second"
    train(tiny_config(*ARGS, f"logger={backend}"), first)
    train(tiny_config(*ARGS, f"logger={backend}", "seed=11"), second)
    if backend == "wandb":
        pattern = "logs/wandb/offline-run-*/run-*.wandb"
    else:
        pattern = "logs/mlruns/*/*/metrics/eval/reward"
    assert len(list(first.glob(pattern))) == 1
    assert len(list(second.glob(pattern))) == 1


def test_missing_backend_package_fails_before_training(compose, monkeypatch):
    real = config_module.importlib.util.find_spec
    monkeypatch.setattr(
        config_module.importlib.util,
        "find_spec",
        lambda name, *a: None if name == "wandb" else real(name, *a),
    )
    with pytest.raises(ConfigError, match=r"needs the 'wandb' package: pip install -e \"\.\[wandb\]\""):
        validate(compose("logger=wandb"))
