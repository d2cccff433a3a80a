"""A key the config does not have (recipes/unknown_options.py): the line after Hydra's refusal
names the keys of that node, each list checked against the schema dataclass's own fields, and
the closest one."""

from __future__ import annotations

import dataclasses
import sys

import pytest
from hydra import compose, initialize_config_dir

from s3rl_torchrl.algorithms.sac import SACConfig
from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.recipes import evaluate as eval_recipe
from s3rl_torchrl.recipes import launch_checks as checks
from s3rl_torchrl.recipes.evaluate import EvalCommandConfig
from s3rl_torchrl.recipes.unknown_options import describe_unknown_option
from s3rl_torchrl.trainer import register_configs
from s3rl_torchrl.trainer.config import CollectorConfig, TrainConfig
from tests.recipes.test_launch_checks import composed, hydra_app, refused


def fields(schema) -> str:
    return ", ".join(f.name for f in dataclasses.fields(schema))


def starting(schema, prefix: str) -> list[str]:
    return [f.name for f in dataclasses.fields(schema) if f.name.startswith(prefix)]


def composition_error(config_name: str, *overrides: str) -> Exception:
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        with pytest.raises(Exception) as raised:
            compose(config_name=config_name, overrides=list(overrides))
    return raised.value


@pytest.mark.parametrize(
    "config_name, overrides, expected",
    [
        # The training command's key given to s3rl-eval: what follows it is a key there.
        ("evaluate", ["eval.episodes=1"],
         f"unknown option 'eval.episodes': s3rl-x has no 'eval'; its options: "
         f"{fields(EvalCommandConfig)}. Did you mean episodes=1?"),
        ("train", ["algo=sac", "algo.actor_lrr=1e-3"],
         f"unknown option 'algo.actor_lrr': algo (SACConfig) has no 'actor_lrr'; its options: "
         f"{fields(SACConfig)}. Did you mean algo.actor_lr=1e-3?"),
        ("train", ["collector.frames_per_batc=500"],
         f"unknown option 'collector.frames_per_batc': collector (CollectorConfig) has no "
         f"'frames_per_batc'; its options: {fields(CollectorConfig)}. Did you mean "
         f"collector.frames_per_batch=500?"),
        ("train", ["sed=3"],
         f"unknown option 'sed': s3rl-x has no 'sed'; its options: {fields(TrainConfig)}. "
         f"Did you mean seed=3?"),
        # A key cut short that begins several: each of them, in the schema's order.
        ("train", ["algo=sac", "algo.alpha=1e-5"],
         f"unknown option 'algo.alpha': algo (SACConfig) has no 'alpha'; its options: "
         f"{fields(SACConfig)}. Did you mean "
         + " or ".join(f"algo.{name}=1e-5" for name in starting(SACConfig, "alpha")) + "?"),
        ("train", ["algo=sac", "algo.lagrangian_=1"],
         f"unknown option 'algo.lagrangian_': algo (SACConfig) has no 'lagrangian_'; its "
         f"options: {fields(SACConfig)}. Did you mean "
         + ", ".join(f"algo.{name}=1" for name in starting(SACConfig, "lagrangian_")[:-1])
         + f" or algo.{starting(SACConfig, 'lagrangian_')[-1]}=1?"),
        # Nothing close: the options alone.
        ("train", ["algo=sac", "algo.zzz=1"],
         f"unknown option 'algo.zzz': algo (SACConfig) has no 'zzz'; its options: "
         f"{fields(SACConfig)}."),
    ],
)
def test_the_line_names_the_nodes_keys_and_the_closest(config_name, overrides, expected):
    assert describe_unknown_option(composition_error(config_name, *overrides), "s3rl-x") == expected


def test_other_errors_get_no_line():
    assert describe_unknown_option(composition_error("train", "seed=abc"), "s3rl-x") is None
    assert describe_unknown_option(ValueError("Could not override 'x'"), "s3rl-x") is None


def test_the_command_prints_it_after_hydras_message(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["s3rl-eval", "checkpoint=run", "eval.episodes=1"])
    with pytest.raises(SystemExit) as stop:
        eval_recipe.main()
    assert stop.value.code == 1  # Hydra's status
    err = capsys.readouterr().err.strip().splitlines()
    assert "Could not override 'eval.episodes'." in err  # Hydra's own message stays
    assert err[-1] == (
        f"s3rl-eval: unknown option 'eval.episodes': s3rl-eval has no 'eval'; its options: "
        f"{fields(EvalCommandConfig)}. Did you mean episodes=1?"
    )
    assert list(tmp_path.iterdir()) == []


def test_a_sweeps_refused_jobs_name_it(tmp_path, capsys):
    with hydra_app():
        cfg = composed("experiment=tiny", f"hydra.sweep.dir={tmp_path / 'multirun'}",
                       task=["experiment=tiny", "algo=sac", "algo.n_stepp=1,3"])
        lines = refused(capsys, lambda: checks.LaunchChecks().on_multirun_start(cfg))
    assert lines[1:] == [
        f"s3rl-train:   experiment=tiny algo=sac algo.n_stepp={value}: unknown option "
        f"'algo.n_stepp': algo (SACConfig) has no 'n_stepp'; its options: "
        f"{fields(SACConfig)}. Did you mean algo.n_step={value}?"
        for value in ("1", "3")
    ]


@pytest.mark.parametrize(
    "argv, option, package, extra",
    [
        (["-m", "+search=lagrangian_target", "experiment=tiny"], "hydra/sweeper/optuna",
         "hydra-optuna-sweeper", "search"),
        (["-m", "hydra/launcher=parallel", "experiment=tiny"], "hydra/launcher/joblib",
         "hydra-joblib-launcher", "sweep"),
    ],
)
def test_an_option_of_a_plugin_not_installed_names_its_extra(
    argv, option, package, extra, tmp_path, monkeypatch, capsys
):
    from hydra.core.config_store import ConfigStore
    from hydra.core.plugins import Plugins

    from s3rl_torchrl.recipes import train as train_recipe

    # A plugin registers its options in Hydra's ConfigStore when Hydra imports it: without
    # them, Hydra stops as it does where the plugin is not installed.
    register_configs()
    Plugins.instance()
    group, name = option.rsplit("/", 1)
    monkeypatch.delitem(ConfigStore.instance().repo["hydra"][group.split("/")[1]],
                        f"{name}.yaml", raising=False)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["s3rl-train", *argv])
    with pytest.raises(SystemExit) as stop:
        train_recipe.main()
    assert stop.value.code == 1  # Hydra's status
    err = capsys.readouterr().err.strip().splitlines()
    assert any(f"'{option}'" in line for line in err[:-1])  # Hydra's own message stays
    assert err[-1] == (
        f"s3rl-train: '{option}' comes with Hydra's plugin {package}, which is not installed: "
        f"pip install 's3rl-torchrl[{extra}]' (in a checkout: pip install -e '.[{extra}]'; "
        "`make setup` installs it)."
    )
    assert list(tmp_path.iterdir()) == []
