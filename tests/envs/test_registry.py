"""The registry across families: ids, lookups, the docs table, import without optional packages."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import gymnasium as gym
import pytest

from s3rl_torchrl.envs import TASKS, TaskSpec, get_task, task_names
from s3rl_torchrl.envs.registry import PAPER_TASK_IDS, tasks_markdown_table

DOCS = Path(__file__).resolve().parents[2] / "docs" / "tasks.md"

# The S3RL paper's Table 1 plus SafetyDroneCircle-v0 from §4's text and Figure 2, typed from the
# paper.
PAPER = {
    "SafetyCarRun-v0", "SafetyBallRun-v0", "SafetyBallCircle-v0", "SafetyCarCircle-v0",
    "SafetyDroneRun-v0", "SafetyAntRun-v0", "SafetyAntCircle-v0", "SafetyDroneCircle-v0",
    "SafetyPointCircle1Gymnasium-v0", "SafetyCarCircle1Gymnasium-v0",
    "SafetyHalfCheetahVelocityGymnasium-v1", "SafetyHopperVelocityGymnasium-v1",
    "SafetySwimmerVelocityGymnasium-v1", "SafetyWalker2dVelocityGymnasium-v1",
    "SafetyAntVelocityGymnasium-v1", "SafetyHumanoidVelocityGymnasium-v1",
    "SafetyPointGoal1Gymnasium-v0",
}


def test_every_paper_task_is_registered():
    assert set(PAPER_TASK_IDS) == PAPER
    for name in PAPER:
        spec = get_task(name)
        assert name in task_names()
        # Every paper task has the paper's default cost limit (Table 3).
        assert spec.cost_limit == 10.0


def test_entries_are_consistent():
    families = {spec.family for spec in TASKS.values()}
    assert families == {"velocity", "bullet", "circle", "goal"}
    for name, spec in TASKS.items():
        assert isinstance(spec, TaskSpec) and spec.env_id == name
        assert spec.max_episode_steps > 0 and spec.obs_dim > 0 and spec.act_dim > 0
        assert spec.cost_limit >= 0 and spec.cost_rule.startswith("1 if ")
        for target in (spec.alias_of, spec.variant_of):
            assert target is None or TASKS[target].alias_of is None
        if spec.alias_of is not None:  # an alias is the same task under another id
            main = TASKS[spec.alias_of]
            same = ("family", "max_episode_steps", "cost_limit", "obs_dim", "act_dim", "cost_rule")
            assert all(getattr(spec, f) == getattr(main, f) for f in same), name
        # The id make_env builds is in Gymnasium's registry with the task's time limit.
        registered = spec.registered_as or name
        assert gym.spec(registered).max_episode_steps == spec.max_episode_steps


def test_task_names_filters():
    every = task_names()
    assert every == sorted(TASKS)
    main = task_names(include_variants=False, include_aliases=False)
    assert "SafetyHalfCheetahVelocity-v1" in main
    assert "SafetyHalfCheetahVelocityGymnasium-v1" not in main
    assert "SafetyHalfCheetahVelocityMujocoV5-v1" not in main
    assert set(task_names(family="bullet")) == {s.env_id for s in TASKS.values() if s.family == "bullet"}
    families = ("velocity", "bullet", "circle", "goal")
    assert set().union(*(task_names(family=f) for f in families)) == set(every)


def test_unknown_task_lists_every_family():
    with pytest.raises(ValueError, match="Unknown task 'SafetyBallRun-v9'") as err:
        get_task("SafetyBallRun-v9")
    for name in ("SafetyBallRun-v0", "SafetyPointCircle1-v0", "SafetyHopperVelocity-v1",
                 "SafetyPointGoal1-v0"):
        assert name in str(err.value)


def test_docs_table_is_the_registry():
    text = DOCS.read_text()
    block = re.search(r"<!-- tasks-table:start -->\n(.*?)\n<!-- tasks-table:end -->", text, re.S)
    assert block is not None, "docs/tasks.md lost its table markers"
    assert block.group(1) == tasks_markdown_table(), (
        "docs/tasks.md's task table differs from the registry; regenerate it (see the comment "
        "above the table)"
    )
    rows = [line for line in block.group(1).splitlines()[2:]]
    assert len(rows) == len(task_names(include_aliases=True)) - sum(
        s.alias_of is not None for s in TASKS.values()
    )
    # Every row has the header's 9 cells (a bare '|' in a cost rule would add one).
    assert all(len(re.split(r"(?<!\\)\|", row)) == 11 for row in rows)


@pytest.mark.parametrize("missing", [("bullet_safety_gym", "pybullet"), ("pybullet",)])
# Re-importing bullet_safety_gym (the second case) registers its gymnasium ids a second time.
@pytest.mark.filterwarnings("ignore:.*Overriding environment:UserWarning")
def test_package_imports_without_the_bullet_packages(missing, monkeypatch):
    # A fresh import of this package with the optional packages unimportable.
    for name in [m for m in sys.modules if m.split(".")[0] in ("s3rl_torchrl", "bullet_safety_gym")]:
        monkeypatch.delitem(sys.modules, name)
    for name in missing:
        monkeypatch.setitem(sys.modules, name, None)  # makes `import name` raise ImportError
    envs = importlib.import_module("s3rl_torchrl.envs")
    importlib.import_module("s3rl_torchrl.trainer")
    assert "SafetyBallRun-v0" in envs.task_names()
    envs.make_env("SafetyHopperVelocity-v1").close()  # other families unaffected
    with pytest.raises(ImportError, match=r's3rl-torchrl\[bullet\]".*--no-deps bullet-safety-gym'):
        envs.make_env("SafetyBallRun-v0")
