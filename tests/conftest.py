"""Test-session settings shared by every area."""

from __future__ import annotations

import functools
import os

import pytest
import torch

# First, before any test module imports MuJoCo (Gymnasium's robots, the benchmarks): the
# package picks MuJoCo's headless GL backend on import, which MuJoCo reads once, when it is
# first imported (s3rl_torchrl/_render_backend.py).
import s3rl_torchrl  # noqa: F401, E402

# Under pytest-xdist (make test: -n 2) each worker keeps to one intra-op thread: two workers
# with two threads each on two cores stall one another (docs/benchmarks.md, threads).
if os.environ.get("PYTEST_XDIST_WORKER"):
    torch.set_num_threads(1)


@functools.cache
def _register_configs_once() -> None:
    # Storing the schemas takes ~0.4 s and the suite composes hundreds of configs; a test that
    # changes a registry calls register_configs() itself, before and after (test_tasks.py).
    from s3rl_torchrl.trainer import register_configs

    register_configs()


# Small fixtures that shrink experiments to seconds (BenchMARL style), for every area's tests.
def compose_train(*overrides: str, return_hydra_config: bool = False):
    """The Hydra config ``s3rl-train`` would get with these overrides (not validated); with
    ``return_hydra_config``, its ``hydra`` node too (the sweep's directories)."""
    from hydra import compose, initialize_config_dir

    from s3rl_torchrl.recipes import config_dir

    _register_configs_once()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return compose(
            config_name="train", overrides=list(overrides), return_hydra_config=return_hydra_config
        )


@pytest.fixture
def compose():
    """``compose(*overrides)``: the Hydra config ``s3rl-train`` would get."""
    return compose_train


@pytest.fixture
def tiny_config():
    """A validated ``experiment=tiny`` config; extra overrides as arguments."""

    from s3rl_torchrl.trainer import validate

    def make(*overrides: str):
        return validate(compose_train("experiment=tiny", *overrides))

    return make
