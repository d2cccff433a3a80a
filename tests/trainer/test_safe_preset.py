"""experiment=safe's per-task settings, task by task, against a table written by hand.

Every registered id (aliases and opt-in variants included) under the two SAC-family algorithms
the preset was chosen with: the Lagrangian's rate and warm-up, the cost critics' read and the
cost limit. The table below is the expectation, not a copy of the preset's own table
(s3rl_torchrl/trainer/presets.py): a change of any task's value, or of which ids share it, fails
here."""

from __future__ import annotations

import pytest

from s3rl_torchrl.envs import get_task, task_names
from s3rl_torchrl.trainer import validate
from s3rl_torchrl.trainer.presets import SAFE_TASK_SETTINGS

# The preset's defaults (configs/experiment/safe.yaml, configs/critic_settings/sound.yaml); the
# warm-up defaults to the random collect, 20 whole episodes of the task.
DEFAULTS = {"lagrangian_lr": 3e-4, "cost_critic_read": "max", "cost_limit": 10.0}
# The tasks with values of their own: the main id and the paper's alias share them; the v5-robot
# variants (SafetyHopperVelocityMujocoV5-v1) are other tasks and get none.
HOPPER = {"cost_critic_read": "mean"}
GOAL = {"lagrangian_lr": 3e-6, "lagrangian_warmup_frames": 100_000, "cost_limit": 25.0}
OWN = {
    "SafetyHopperVelocity-v1": HOPPER,
    "SafetyHopperVelocityGymnasium-v1": HOPPER,
    "SafetyPointGoal1-v0": GOAL,
    "SafetyPointGoal1Gymnasium-v0": GOAL,
}


def expected(task: str) -> dict:
    warmup = 20 * get_task(task).max_episode_steps
    return {**DEFAULTS, "lagrangian_warmup_frames": warmup, **OWN.get(task, {})}


def test_the_table_names_registered_ids():
    assert set(OWN) <= set(task_names())
    # The preset's table is keyed by main ids: an alias takes its main id's entry.
    assert set(SAFE_TASK_SETTINGS) <= set(task_names(include_aliases=False))


@pytest.mark.parametrize("algo", ["sac_lag", "s3rl"])
@pytest.mark.parametrize("task", task_names())
def test_safe_preset_settings_of_every_task(task, algo, compose):
    cfg = validate(compose("experiment=safe", f"task={task}", f"algo={algo}", "compile=false"))
    got = {
        "lagrangian_lr": cfg.algo.lagrangian_lr,
        "lagrangian_warmup_frames": cfg.algo.lagrangian_warmup_frames,
        "cost_critic_read": cfg.algo.cost_critic_read,
        "cost_limit": cfg.task.cost_limit,
    }
    assert got == expected(task)


@pytest.mark.parametrize("task", ["SafetyHopperVelocity-v1", "SafetyPointGoal1Gymnasium-v0"])
def test_the_command_line_wins_over_a_tasks_own_values(task, compose):
    cfg = validate(compose("experiment=safe", f"task={task}", "algo=sac_lag", "compile=false",
                           "algo.cost_critic_read=min", "algo.lagrangian_lr=1e-5",
                           "algo.lagrangian_warmup_frames=0", "task.cost_limit=7"))
    assert (cfg.algo.cost_critic_read, cfg.algo.lagrangian_lr) == ("min", 1e-5)
    assert (cfg.algo.lagrangian_warmup_frames, cfg.task.cost_limit) == (0, 7.0)


@pytest.mark.parametrize("algo", ["ppo_lag", "ddpg_lag"])
@pytest.mark.parametrize("task", ["SafetyHopperVelocity-v1", "SafetyPointGoal1-v0"])
def test_other_families_take_the_tasks_lagrangian_and_limit(task, algo, compose):
    # The read is the SAC family's (its cost-critic pair); the other families have none and
    # compose with the task's other values.
    cfg = validate(compose("experiment=safe", f"task={task}", f"algo={algo}", "compile=false"))
    want = expected(task)
    assert not hasattr(cfg.algo, "cost_critic_read")
    assert (cfg.algo.lagrangian_lr, cfg.algo.lagrangian_warmup_frames, cfg.task.cost_limit) == (
        want["lagrangian_lr"], want["lagrangian_warmup_frames"], want["cost_limit"])


def test_fsrl_critics_keep_their_read_under_the_preset(compose):
    cfg = validate(compose("experiment=safe", "task=SafetyHopperVelocity-v1", "critic=fsrl"))
    assert cfg.algo.cost_critic_read == "min"


@pytest.mark.parametrize("experiment", ["paper", "quick", "tiny"])
@pytest.mark.parametrize("task", ["SafetyPointGoal1-v0", "SafetyPointGoal1Gymnasium-v0"])
def test_other_experiments_take_no_lagrangian_or_limit_of_the_preset(task, experiment, compose):
    cfg = validate(compose(f"experiment={experiment}", f"task={task}", "algo=sac_lag"))
    assert cfg.task.cost_limit == 10.0
    assert cfg.algo.lagrangian_lr != GOAL["lagrangian_lr"]
    assert cfg.algo.lagrangian_warmup_frames != GOAL["lagrangian_warmup_frames"]


@pytest.mark.parametrize("overrides", [("experiment=quick",), ("experiment=paper", "critic=sound")])
def test_the_sound_read_goes_with_the_critic_choice(overrides, compose):
    # The read is critic=sound's on the task, whichever experiment picks it (quick does).
    for task, read in [("SafetyHopperVelocity-v1", "mean"),
                       ("SafetyHopperVelocityGymnasium-v1", "mean"),
                       ("SafetyHopperVelocityMujocoV5-v1", "max")]:
        cfg = validate(compose(*overrides, f"task={task}", "algo=sac_lag", "compile=false"))
        assert cfg.algo.cost_critic_read == read, task
