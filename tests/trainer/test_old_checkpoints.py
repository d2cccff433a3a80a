"""Checkpoints written before the algorithm families and the trainer hooks (commit 8e0ee0c:
one flat ``AlgoConfig``, the critic diagnostics' episodes under their own key, the probes in the
loop) still load and resume, into the run the old code gave uninterrupted.

The fixtures (``tests/data/old_checkpoints/``, made by ``make_old_checkpoints.py`` with that
code) are runs stopped mid-epoch and the ``metrics.csv`` and ``final_eval.json`` of the same
command never stopped."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from s3rl_torchrl.algorithms import DDPGConfig, PPOConfig, SACConfig
from s3rl_torchrl.trainer import train
from s3rl_torchrl.trainer.config import saved_config_node, saved_train_config
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy
from s3rl_torchrl.trainer.resume import resume_config, saved_config
from tests.trainer.test_resume import final, rows

FIXTURES = Path(__file__).resolve().parents[1] / "data" / "old_checkpoints"
CASES = {"s3rl": SACConfig, "ddpg_lag": DDPGConfig, "ppo_lag": PPOConfig}


def old_run(case: str, tmp_path: Path) -> Path:
    run = tmp_path / case
    shutil.copytree(FIXTURES / case / "run", run)
    return run


@pytest.mark.parametrize("case", sorted(CASES))
def test_an_old_checkpoint_resumes_into_the_uninterrupted_run(case, tmp_path):
    run = old_run(case, tmp_path)
    cfg = resume_config(run, echo=False)  # `s3rl-train resume=<run>` alone
    assert type(cfg.algo) is CASES[case] and cfg.diagnostics.probes
    result = train(cfg, tmp_path / "unused")
    assert result.status == "finished"
    expected = FIXTURES / case / "expected"
    assert rows(run) == rows(expected)
    assert final(run) == final(expected)
    # The resume is recorded as exact and as changing nothing (the dropped fields were never
    # read by the run's family).
    resume = json.loads((run / "config.json").read_text())["resumes"][-1]
    assert resume["exact"] and resume["changed"] == {}


@pytest.mark.parametrize("case", sorted(CASES))
def test_an_old_config_loads_with_its_familys_fields(case):
    saved = saved_config(FIXTURES / case / "run")
    assert {"ppo_epochs", "exploration_noise", "alpha_lr", "n_step"} <= set(saved["algo"])
    assert "diagnostics" not in saved
    cfg = saved_train_config(saved)
    assert type(cfg.algo) is CASES[case]
    kept = {name for name in saved["algo"] if hasattr(cfg.algo, name)}
    for name in kept:  # what the family has keeps its saved value
        value = getattr(cfg.algo, name)
        value = vars(value) if hasattr(value, "__dict__") else value
        assert value == saved["algo"][name], name
    dropped = set(saved["algo"]) - kept
    assert dropped == {
        "s3rl": {"exploration_noise", "ppo_epochs", "gae_lambda", "clip_epsilon",
                 "critic_coeff", "max_grad_norm", "cost_surrogate"},
        "ddpg_lag": {"update_order", "alpha_lr", "alpha_init", "auto_alpha", "cost_entropy",
                     "cost_critic_read", "cost_nonnegative", "entropy_rescaling", "ppo_epochs",
                     "gae_lambda", "clip_epsilon", "critic_coeff", "max_grad_norm",
                     "cost_surrogate"},
        "ppo_lag": {"tau", "n_step", "update_order", "alpha_lr", "alpha_init", "auto_alpha",
                    "cost_entropy", "cost_critic_read", "cost_nonnegative",
                    "entropy_rescaling", "exploration_noise"},
    }[case]
    # Those runs measured the probes at every epoch: they keep measuring them.
    assert cfg.diagnostics.probes and cfg.diagnostics.critics


def test_a_config_of_this_version_loads_unchanged(tiny_config):
    from s3rl_torchrl.trainer.config import to_container

    for algo in CASES:
        cfg = tiny_config(f"algo={algo}")
        assert saved_train_config(to_container(cfg)) == cfg
    node = saved_config_node({**to_container(tiny_config("algo=ppo")), "diagnostics": {}})
    assert node.diagnostics.probes is False  # a config that says so keeps them off


def test_s3rl_eval_loads_an_old_checkpoint(tmp_path):
    actor, cfg = load_policy(old_run("s3rl", tmp_path))
    assert type(cfg.algo) is SACConfig and cfg.algo.name == "s3rl"
    assert actor is not None
