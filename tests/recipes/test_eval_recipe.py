"""``s3rl-eval``'s defaults: the run's own evaluation settings, given values win."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import ConfigError, TrainConfig, Trainer, register_configs, validate
from s3rl_torchrl.trainer.builders import build_envs
from s3rl_torchrl.trainer.evaluate_checkpoint import eval_settings, evaluate_checkpoint
from s3rl_torchrl.trainer.evaluation import evaluate


def run_config(**eval_fields) -> TrainConfig:
    cfg = TrainConfig()
    cfg.task.name = "SafetyHopperVelocity-v1"
    cfg.seed = 7
    for name, value in eval_fields.items():
        setattr(cfg.eval, name, value)
    return cfg


def test_settings_default_to_the_runs_own():
    cfg = run_config(final_episodes=3, num_envs=1, max_steps=50, episodes=1)
    s = eval_settings(cfg)
    # The final table's: final_episodes (not the per-epoch episodes), the test envs' seed.
    assert (s.episodes, s.num_envs, s.seed, s.max_steps) == (3, 1, 100_007, 50)
    assert s.sources == {
        "episodes": "the run's eval.final_episodes",
        "num_envs": "the run's eval.num_envs",
        "seed": "the run's test envs: its seed + 100000",
        "max_steps": "the run's eval.max_steps",
    }
    assert s.describe().startswith("episodes=3 (the run's eval.final_episodes), num_envs=1 (")


def test_given_settings_win_one_by_one():
    cfg = run_config(final_episodes=3, num_envs=1, max_steps=50)
    s = eval_settings(cfg, max_steps=1000, seed=0)
    assert (s.episodes, s.num_envs, s.seed, s.max_steps) == (3, 1, 0, 1000)
    assert s.sources["max_steps"] == s.sources["seed"] == "given"
    assert s.sources["episodes"] == "the run's eval.final_episodes"
    assert "max_steps=1000 (given)" in s.describe()


def test_a_config_without_max_steps_uses_the_tasks_episode_length():
    # validate() fills eval.max_steps; a config saved without it falls back to the registry's.
    s = eval_settings(run_config(max_steps=None))
    assert (s.max_steps, s.sources["max_steps"]) == (1000, "the task's episode length")


def test_default_evaluation_is_the_runs_test_envs_evaluation(tmp_path):
    # The expectation built independently: the trained actor on a freshly built copy of the
    # run's own test envs (builders.build_envs), with the run's final-evaluation settings.
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = validate(compose(config_name="train", overrides=[
            "experiment=tiny", "algo=sac", "collector.total_frames=200",
            "eval.final_episodes=3", "eval.max_steps=20",
        ]))
    trainer = Trainer(cfg, tmp_path)
    trainer.run()
    _, test_env = build_envs(cfg)
    expected = evaluate(test_env, trainer.agent.actor, 3, 20)
    test_env.close()

    result, train_cfg = evaluate_checkpoint(tmp_path)
    assert result.episodes == 3 and result.episode_lengths == [20, 20, 20]
    assert result.episode_rewards == expected.episode_rewards
    assert result.episode_costs == expected.episode_costs
    assert train_cfg.eval.max_steps == 20
    # A given value still wins (the old default would have rolled out 1000 steps).
    shorter, _ = evaluate_checkpoint(tmp_path, episodes=1, max_steps=7)
    assert (shorter.episodes, shorter.length_mean) == (1, 7.0)


def test_command_config_checks_given_values_and_the_checkpoint():
    from s3rl_torchrl.recipes.evaluate import EvalCommandConfig

    EvalCommandConfig(checkpoint="run").check()  # every setting the run's
    with pytest.raises(ConfigError, match="'episodes'.*null for the run's own"):
        EvalCommandConfig(checkpoint="run", episodes=0).check()
    with pytest.raises(ConfigError, match="missing checkpoint=.*e.g. s3rl-eval checkpoint="):
        EvalCommandConfig(checkpoint=" ").check()
