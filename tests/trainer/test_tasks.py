"""Every task family through the trainer: task options carry the registry's defaults, and tiny
end-to-end trainings run on a Bullet task and on the Circle tasks."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from s3rl_torchrl.envs import get_task, registry, task_names
from s3rl_torchrl.trainer import ConfigError, train, validate
from s3rl_torchrl.trainer.config import register_configs
from s3rl_torchrl.trainer.presets import safe_task_settings

BIN = Path(sys.executable).parent
# One Bullet task and every Circle and Goal task (their family's main ids; the paper's `...Gymnasium`
# aliases build the same envs).
E2E_TASKS = [
    "SafetyBallRun-v0",
    *task_names(False, False, family="circle"),
    *task_names(False, False, family="goal"),
]


@pytest.mark.parametrize("task", task_names(include_aliases=False))
def test_task_option_carries_the_registry_defaults(task, compose):
    spec = get_task(task)
    cfg = validate(compose(f"task={task}", "compile=false"))
    assert cfg.task.cost_limit == spec.cost_limit
    # eval.max_steps defaults to null: one whole episode of the task per evaluation rollout.
    assert cfg.eval.max_steps == spec.max_episode_steps


@pytest.mark.parametrize("task", task_names(include_aliases=False))
def test_safe_preset_validates_with_each_tasks_own_values(task, compose):
    # A value of the preset's table the algo config would refuse (e.g. a cost_critic_read
    # outside COST_CRITIC_READS) fails here, not when a run of that task starts.
    own = safe_task_settings(task)
    cfg = validate(compose("experiment=safe", f"task={task}", "compile=false"))
    assert cfg.task.cost_limit == (own.cost_limit or get_task(task).cost_limit)
    for name, value in dataclasses.asdict(own).items():
        if value is not None and name != "cost_limit":
            assert getattr(cfg.algo, name) == value, name


def test_overrides_win_over_registry_defaults(compose):
    cfg = validate(compose("task=SafetyBallRun-v0", "compile=false", "eval.max_steps=7",
                           "task.cost_limit=3"))
    assert (cfg.eval.max_steps, cfg.task.cost_limit) == (7, 3.0)


def test_registry_cost_limit_reaches_the_task_option(compose, monkeypatch):
    # A registry entry with another limit: the generated ConfigStore option carries it.
    spec = dataclasses.replace(get_task("SafetyCarRun-v0"), cost_limit=25.0)
    monkeypatch.setitem(registry.TASKS, "SafetyCarRun-v0", spec)
    try:
        register_configs()
        assert validate(compose("task=SafetyCarRun-v0", "compile=false")).task.cost_limit == 25.0
    finally:
        monkeypatch.undo()
        register_configs()
    assert validate(compose("task=SafetyCarRun-v0", "compile=false")).task.cost_limit == 10.0


def test_missing_optional_package_fails_in_the_config_check(compose, monkeypatch):
    for name in ("bullet_safety_gym.envs.builder", "pybullet"):
        monkeypatch.setitem(sys.modules, name, None)  # makes `import name` raise ImportError
    with pytest.raises(ConfigError, match=r"'task.name'.*s3rl-torchrl\[bullet\]"):
        validate(compose("task=SafetyBallRun-v0", "compile=false"))


@pytest.mark.parametrize("task", E2E_TASKS)
def test_tiny_training_run(task, tiny_config, tmp_path):
    spec = get_task(task)
    cfg = tiny_config(f"task={task}")
    result = train(cfg, tmp_path)
    assert result.status == "finished"
    assert result.counters.frames == cfg.collector.total_frames
    final = json.loads((tmp_path / "final_eval.json").read_text())
    assert final["episodes"] == cfg.eval.final_episodes
    # tiny evaluates 50-step rollouts, shorter than every episode length here.
    assert 1 <= final["length_mean"] <= min(cfg.eval.max_steps, spec.max_episode_steps)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["task"] == {"name": task, "cost_limit": spec.cost_limit}


def _run(script: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(BIN / script), *args], cwd=cwd, env={**os.environ, "HYDRA_FULL_ERROR": "0"},
        capture_output=True, text=True, timeout=600,
    )


def test_s3rl_train_and_eval_cli_on_a_bullet_task(tmp_path):
    run_dir, eval_dir = tmp_path / "run", tmp_path / "eval"
    out = _run("s3rl-train", "task=SafetyBallRun-v0", "experiment=tiny",
               "collector.total_frames=200", "collector.frames_per_epoch=200",
               f"hydra.run.dir={run_dir}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "| run | episodes | reward | cost | length | safe steps (%) |" in out.stdout
    assert json.loads((run_dir / "final_eval.json").read_text())["episodes"] == 2
    # 200-step rollouts: the Ball never terminates, so each episode lasts the 100-step time
    # limit (without max_steps, s3rl-eval takes the run's own: 50 under experiment=tiny).
    out = _run("s3rl-eval", f"checkpoint={run_dir}", "episodes=2", "num_envs=1", "max_steps=200",
               f"hydra.run.dir={eval_dir}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    result = json.loads((eval_dir / "eval.json").read_text())
    assert result["episodes"] == 2 and result["length_mean"] == 100.0
