"""The committed multiruns (configs/sweep/*.yaml, shipped with the package, and the research
wing's research/configs/sweep/*.yaml, launched with `hydra.searchpath=[file://research/configs]`):
every job they launch is a valid config, and no two jobs, of one sweep or of two, share a run
directory (a 1M-frame run is ~30 minutes; a bad override or a shared directory should fail here,
not after the first jobs have trained)."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest
import yaml
from omegaconf import OmegaConf, open_dict

from s3rl_torchrl.algorithms.config import REMOVED_OPTIONS
from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.recipes.launch_checks import sweep_overrides
from s3rl_torchrl.trainer import validate
from tests.conftest import compose_train

ROOT = Path(__file__).resolve().parents[2]
# The research wing's sweeps (the critic selection's rounds, the evidence) are not in the
# package's configs/: Hydra finds them once research/configs is on its search path.
RESEARCH_CONFIGS = ROOT / "research" / "configs"
SEARCHPATH = f"hydra.searchpath=[file://{RESEARCH_CONFIGS}]"
SWEEP_FILES = {
    p.stem: p
    for directory in (config_dir() / "sweep", RESEARCH_CONFIGS / "sweep")
    for p in directory.glob("*.yaml")
}


def sweep_params(name: str) -> dict:
    return yaml.safe_load(SWEEP_FILES[name].read_text())["hydra"]["sweeper"]["params"]


def removed_options(name: str) -> set[str]:
    """The options a sweep varies that have left the package (``REMOVED_OPTIONS``)."""
    return {key.removeprefix("algo.") for key in sweep_params(name)} & set(REMOVED_OPTIONS)


# A sweep of a removed option runs at the last commit that had it (its header says which);
# this version cannot compose it.
RETIRED = sorted(name for name in SWEEP_FILES if removed_options(name))
SWEEPS = sorted(set(SWEEP_FILES) - set(RETIRED))


def is_research(name: str) -> bool:
    return SWEEP_FILES[name].is_relative_to(RESEARCH_CONFIGS)


def sweep_jobs(name: str) -> list[list[str]]:
    """Each job's overrides, expanded the way Hydra's basic sweeper expands ``params``."""
    arguments = [f"{key}={value}" for key, value in sweep_params(name).items()]
    first = [SEARCHPATH] if is_research(name) else []
    return [[*first, f"+sweep={name}", *job] for job in sweep_overrides(arguments)]


def test_the_committed_sweeps_are_found():
    # An empty glob would parametrise nothing and pass silently.
    assert {"evidence", "table1", "critic_selection_goal4", "critic_selection_goal5"} <= set(SWEEPS)
    assert RETIRED == ["critic_selection_ballrun"]  # algo.cost_gamma
    # The package ships the reference's sweeps (Table 1 under the recommended preset, the
    # paper-settings reproduction), not the research rounds.
    shipped = {"table1", "table1_v2", "reproduction"}
    assert {p.stem for p in (config_dir() / "sweep").glob("*.yaml")} == shipped
    assert all(is_research(name) for name in SWEEPS if name not in shipped)
    # Issue 63's runs.
    assert len(sweep_jobs("reproduction")) == 36  # six tasks x two algos x three seeds
    # Issue 60's evidence: one run per committed run of Table 1 (the same algo, task and seed),
    # which make report pairs it with.
    committed = {
        (algo, f"Safety{task}", seed.name)
        for tree in ("safe_sound", "table1")
        for seed in (ROOT / "results" / tree).glob("*/seed*")
        for algo, task in [seed.parent.name.split("_Safety")]
    }
    jobs = {(o["algo"], o["task"], f"seed{o['seed']}")
            for o in (dict(o.split("=", 1) for o in job) for job in sweep_jobs("table1_v2"))}
    assert len(committed) == 96 and jobs == committed


@pytest.mark.parametrize("name", RETIRED)
def test_a_sweep_of_a_removed_option_names_the_commit_it_runs_at(name):
    assert is_research(name)  # the package's own sweeps vary nothing it does not have
    header = SWEEP_FILES[name].read_text().split("hydra:")[0]
    for option in removed_options(name):
        assert f"commit {REMOVED_OPTIONS[option].last_commit}" in header, (name, option)


def test_a_research_sweep_needs_the_research_search_path():
    # Without research/configs on the search path the package's configs do not know it ...
    with pytest.raises(Exception, match="critic_selection"):
        compose_train("+sweep=critic_selection")
    # ... with it (as research/README.md launches it), it composes.
    cfg = compose_train(SEARCHPATH, "+sweep=critic_selection", return_hydra_config=True)
    assert cfg.hydra.sweep.dir == "runs/critic_selection"
    assert cfg.hydra.sweeper.params["critic"] == "sound"


@functools.cache
def validated_job_directories(name: str) -> tuple[str, ...]:
    """Compose and validate every job of the sweep; its run directories, in launch order."""
    directories = []
    for overrides in sweep_jobs(name):
        cfg = compose_train(*overrides, return_hydra_config=True)
        # hydra.runtime.choices is filled in by a launch, not by compose: fill the one
        # choice a subdir names (the critic) from the job's overrides.
        choices = dict(o.split("=", 1) for o in overrides if "." not in o.split("=")[0])
        OmegaConf.update(cfg, "hydra.runtime.choices", {"critic": choices.get("critic", "")},
                         force_add=True)
        directories.append(f"{cfg.hydra.sweep.dir}/{cfg.hydra.sweep.subdir}")
        with open_dict(cfg):
            del cfg["hydra"]
        validate(cfg)
    return tuple(directories)


@pytest.mark.parametrize("name", SWEEPS)
def test_every_job_of_a_sweep_validates_in_its_own_directory(name):
    directories = validated_job_directories(name)
    assert directories
    shared = {d for d in directories if directories.count(d) > 1}
    assert not shared, f"{name}: several jobs write into {sorted(shared)}"


def test_no_two_sweeps_write_into_the_same_directory():
    owner = {}
    for name in SWEEPS:
        for directory in validated_job_directories(name):
            assert directory not in owner, f"{name} and {owner[directory]} both write {directory}"
            owner[directory] = name
