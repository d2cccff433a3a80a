"""Checkpoints written before the algorithm families and the trainer hooks (commit 8e0ee0c:
one flat ``AlgoConfig``, the critic diagnostics' episodes under their own key, the probes in the
loop) still load and resume, into the run the old code gave uninterrupted.

The fixtures (``tests/data/old_checkpoints/``, made by ``make_old_checkpoints.py`` with that
code) are runs stopped mid-epoch and the ``metrics.csv`` and ``final_eval.json`` of the same
command never stopped.

They were made on one machine, and float rounding differs between CPUs: on an AMD EPYC machine
of this kind the resumed runs differ from them by up to 1.2e-5 relative (PPO-Lag's
``train/loss_objective``; S3RL 1.6e-6, DDPG-Lag 1.6e-7) although every resume is exact there. So
the numbers are compared within :data:`REL`. That a resume continues a run bit for bit is
checked where both runs are made on one machine, a resumed run against the same run never
stopped, by ``tests/trainer/test_resume.py``.

The expected final evaluations count episodes by today's rule (each env copy's first episode of
a rollout: ``episode_statistics``), which the old code did not: ``make_old_checkpoints.py
--expected-only`` remade ``expected/`` with that code and today's rule in its place (2026-12-01).
Their ``metrics.csv`` came out unchanged but for ``eval/seconds``: one episode per epoch is the
same by both rules."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from s3rl_torchrl.algorithms import ConfigError, DDPGConfig, PPOConfig, SACConfig
from s3rl_torchrl.algorithms.config import REMOVED_OPTIONS
from s3rl_torchrl.trainer import train
from s3rl_torchrl.trainer.config import saved_config_node, saved_train_config, to_container
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy
from s3rl_torchrl.trainer.resume import resume_config, saved_config
from tests.trainer.test_resume import final, rows

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "tests" / "data" / "old_checkpoints"
CASES = {"s3rl": SACConfig, "ddpg_lag": DDPGConfig, "ppo_lag": PPOConfig}
# Relative tolerance for the fixtures' numbers: 8x the largest rounding difference measured
# between two machines (module docstring).
REL = 1e-4


def same_run(got, expected) -> bool:
    """``got`` equals ``expected`` up to float rounding: the same keys, list lengths and text,
    numbers (also numbers written as text, as metrics.csv's cells are) within :data:`REL`."""
    if isinstance(expected, dict):
        return got.keys() == expected.keys() and all(
            same_run(got[k], expected[k]) for k in expected
        )
    if isinstance(expected, list):
        return len(got) == len(expected) and all(map(same_run, got, expected))
    try:
        x, y = float(got), float(expected)
    except (TypeError, ValueError):
        return got == expected
    if isinstance(expected, bool) or math.isnan(y):
        return got == expected or (math.isnan(y) and math.isnan(x))
    return math.isclose(x, y, rel_tol=REL, abs_tol=1e-9)


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
    assert same_run(rows(run), rows(expected))
    assert same_run(final(run), final(expected))
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
        if name == "contrastive_cfg":
            # Before phase_at, each contrastive phase ran at the end of its interval.
            assert value == {**saved["algo"][name], "phase_at": "end"}
            continue
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
    for algo in CASES:
        cfg = tiny_config(f"algo={algo}")
        assert saved_train_config(to_container(cfg)) == cfg
    node = saved_config_node({**to_container(tiny_config("algo=ppo")), "diagnostics": {}})
    assert node.diagnostics.probes is False  # a config that says so keeps them off
    # A saved phase_at is kept; only a config from before it gets "end" (module docstring).
    saved = to_container(tiny_config("algo=s3rl"))
    assert saved["algo"]["contrastive_cfg"]["phase_at"] == "start"
    assert saved_train_config(saved).algo.contrastive_cfg.phase_at == "start"
    del saved["algo"]["contrastive_cfg"]["phase_at"]
    assert saved_train_config(saved).algo.contrastive_cfg.phase_at == "end"


def test_a_removed_option_loads_at_its_default_and_is_refused_at_any_other(tiny_config):
    # algo.cost_gamma (the cost critics' own discount) left after commit 6c13fe3; every run
    # saved before then holds it, null unless set.
    cfg = tiny_config("algo=sac_lag")
    saved = to_container(cfg)
    assert "cost_gamma" in REMOVED_OPTIONS and "cost_gamma" not in saved["algo"]
    saved["algo"]["cost_gamma"] = None
    assert saved_train_config(saved) == cfg  # at its default: the run ran as runs do now
    saved["algo"]["cost_gamma"] = 0.9  # a setting this version cannot run
    message = r"'algo\.cost_gamma' is 0\.9, but cost_gamma .* removed.* commit 6c13fe3"
    with pytest.raises(ConfigError, match=message):
        saved_config_node(saved)


def test_the_exported_runs_configs_load():
    # The exported config.json files that hold a removed option (results/, research/results/),
    # one per result tree and algorithm: the reports read them as they are; a resume or an
    # evaluation of their runs reads the config their checkpoints hold, the same but for
    # config.json's history of resumes, through saved_config_node.
    configs = {}
    for tree in ("results", "research/results"):
        for path in sorted((REPO / tree).rglob("config.json")):
            saved = json.loads(path.read_text())
            if set(REMOVED_OPTIONS) & set(saved.get("algo", {})):
                group = (path.relative_to(REPO).parts[: tree.count("/") + 2], saved["algo"]["name"])
                configs.setdefault(group, saved)
    if not configs:
        pytest.skip("no exported run holds a removed option here (not a repository checkout)")
    for group, saved in configs.items():
        saved.pop("resumes", None)
        cfg = saved_train_config(saved)
        assert cfg.algo.name == saved["algo"]["name"] and cfg.seed == saved["seed"], group


def test_s3rl_eval_loads_an_old_checkpoint(tmp_path):
    actor, cfg = load_policy(old_run("s3rl", tmp_path))
    assert type(cfg.algo) is SACConfig and cfg.algo.name == "s3rl"
    assert actor is not None


def test_same_run_tolerates_rounding_only():
    row = {"frames": "200", "eval/reward": "10.0", "probe/auc": "nan", "label": "x"}
    assert same_run([row], [{**row, "eval/reward": "10.0001"}])  # 1e-5 relative
    assert not same_run([row], [{**row, "eval/reward": "10.01"}])
    assert not same_run([row], [{**row, "probe/auc": "0.5"}])
    assert not same_run([row], [row, row]) and not same_run({"a": 1}, {"b": 1})
    assert not same_run({"exact": True}, {"exact": False})
