"""Small fixtures that shrink experiments to seconds (BenchMARL style)."""

from __future__ import annotations

import pytest
from hydra import compose as hydra_compose
from hydra import initialize_config_dir

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import TrainConfig, register_configs, validate

CONFIG_DIR = str(config_dir())


def compose_train(*overrides: str):
    """The Hydra config ``s3rl-train`` would get with these overrides (not validated)."""
    register_configs()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return hydra_compose(config_name="train", overrides=list(overrides))


@pytest.fixture
def compose():
    """``compose(*overrides)``: the Hydra config ``s3rl-train`` would get."""
    return compose_train


@pytest.fixture
def tiny_config():
    """A validated ``experiment=tiny`` config; extra overrides as arguments."""

    def make(*overrides: str) -> TrainConfig:
        return validate(compose_train("experiment=tiny", *overrides))

    return make
