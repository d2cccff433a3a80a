"""``make_env``: TorchRL envs of the velocity tasks, checked against torchrl's plain GymEnv."""

from __future__ import annotations

import pytest
import torch
from tensordict.nn import TensorDictModule
from torchrl.envs import DoubleToFloat, GymEnv, TransformedEnv, default_info_dict_reader
from torchrl.envs.utils import check_env_specs

from s3rl_torchrl.envs import VELOCITY_REGISTRATIONS, get_task, make_env, task_names
from tests.envs._policies import ReplayActions


# Every task of every family, v5 variants included (aliases build the same envs).
@pytest.mark.parametrize("task", task_names(include_aliases=False))
def test_check_env_specs(task):
    env = make_env(task, seed=0)
    check_env_specs(env, seed=0)
    spec = get_task(task)  # the registry's sizes are the built env's
    assert env.observation_spec["observation"].shape == (spec.obs_dim,)
    assert env.action_spec.shape == (spec.act_dim,)
    env.close()


@pytest.mark.parametrize("batching", ["sync_vector", "async_vector", "serial", "parallel"])
def test_batched_env_carries_cost_like_reward(batching):
    env = make_env("SafetyHopperVelocity-v1", num_envs=2, seed=0, batching=batching)
    check_env_specs(env, seed=0)
    td = env.rollout(5, break_when_any_done=False)
    assert td.batch_size == (2, 5)
    assert td["next", "cost"].shape == td["next", "reward"].shape == (2, 5, 1)
    assert td["next", "cost"].dtype == td["next", "reward"].dtype == torch.float32
    env.close()


def test_step_keys_shapes_and_dtypes():
    env = make_env("SafetyHalfCheetahVelocity-v1", seed=0)
    td = env.rollout(4)
    assert td["next", "cost"].shape == td["next", "reward"].shape == (4, 1)
    assert td["next", "cost"].dtype == td["next", "reward"].dtype
    assert td["observation"].dtype == torch.float32
    for key in ("step_count", "episode_reward", "episode_cost", "is_init", "safe"):
        assert ("next", key) in td.keys(True), key
    assert td["next", "step_count"].squeeze(-1).tolist() == [1, 2, 3, 4]
    torch.testing.assert_close(td["next", "episode_reward"], td["next", "reward"].cumsum(0))


def test_matches_plain_gymnasium_v4_and_threshold_rule():
    # The reference: torchrl's own GymEnv over Gymnasium's plain Hopper-v4, reading the x
    # velocity from info; the cost is recomputed here from it with Safety-Gymnasium's rule.
    threshold = 0.0  # below the real limit so that both labels occur in a short rollout
    env = make_env("SafetyHalfCheetahVelocity-v1", seed=5, cost_threshold=threshold)
    plain = GymEnv("HalfCheetah-v4").set_info_dict_reader(default_info_dict_reader(["x_velocity"]))
    plain = TransformedEnv(plain, DoubleToFloat())
    plain.set_seed(5)
    torch.manual_seed(0)
    actions = env.action_spec.rand((40,))
    ours = env.rollout(40, ReplayActions(actions), break_when_any_done=False)
    ref = plain.rollout(40, ReplayActions(actions), break_when_any_done=False)
    torch.testing.assert_close(ours["observation"], ref["observation"], rtol=0, atol=0)
    torch.testing.assert_close(ours["next", "reward"], ref["next", "reward"], rtol=0, atol=0)
    expected_cost = (ref["next", "x_velocity"].float() > threshold).float().reshape(-1, 1)
    torch.testing.assert_close(ours["next", "cost"], expected_cost, rtol=0, atol=0)
    assert 0 < expected_cost.sum() < len(expected_cost)
    torch.testing.assert_close(ours["next", "safe"], expected_cost == 0)


def test_episode_cost_sums_and_resets():
    env = make_env("SafetyHopperVelocity-v1", seed=1, cost_threshold=0.05)
    td = env.rollout(120, break_when_any_done=False)  # random Hopper falls within ~20 steps
    done = td["next", "done"].squeeze(-1)
    assert done.any()
    running = 0.0
    for t in range(td.shape[0]):
        if td["is_init"][t]:
            running = 0.0
            assert td["episode_cost"][t].item() == 0.0
        running += td["next", "cost"][t].item()
        assert td["next", "episode_cost"][t].item() == pytest.approx(running)


def test_truncation_at_1000_steps_is_not_termination():
    env = make_env("SafetyHalfCheetahVelocity-v1", seed=0)
    td = env.rollout(1000, TensorDictModule(lambda obs: torch.zeros(6), ["observation"], ["action"]))
    assert td.shape == (1000,)
    assert td["next", "truncated"][-1].item() and not td["next", "terminated"].any()
    assert not td["next", "truncated"][:-1].any()


def test_bad_arguments_fail_clearly():
    with pytest.raises(ValueError, match="Valid tasks are: .*SafetyHalfCheetahVelocity-v1"):
        make_env("SafetyCheetahVelocity-v1")
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        make_env("SafetyHalfCheetahVelocity-v1", num_envs=0)
    with pytest.raises(ValueError, match="valid choices are sync_vector, async_vector, serial, parallel"):
        make_env("SafetyHalfCheetahVelocity-v1", num_envs=2, batching="threads")


def test_every_alias_builds_the_same_task():
    a = make_env("SafetyWalker2dVelocity-v1", seed=0)
    b = make_env("SafetyWalker2dVelocityGymnasium-v1", seed=0)
    registered = VELOCITY_REGISTRATIONS
    assert (
        registered["SafetyWalker2dVelocity-v1"].task
        is registered["SafetyWalker2dVelocityGymnasium-v1"].task
    )
    torch.testing.assert_close(a.reset()["observation"], b.reset()["observation"])


@pytest.mark.parametrize("batching", ["sync_vector", "serial"])
def test_batched_copies_reset_independently(batching):
    # A copy that ends restarts fresh (counters and sums at 0) while the others carry on:
    # the next root observation is the previous step's next observation unless it just ended.
    env = make_env("SafetyHopperVelocity-v1", num_envs=3, seed=0, batching=batching)
    td = env.rollout(120, break_when_any_done=False)
    done = td["next", "done"].squeeze(-1)
    assert done.sum() >= 3  # random Hoppers fall within ~20 steps
    for i in range(3):
        for t in range(119):
            if done[i, t]:
                assert td["is_init"][i, t + 1].item()
                assert td["step_count"][i, t + 1].item() == 0
                assert td["episode_reward"][i, t + 1].item() == 0
                assert td["episode_cost"][i, t + 1].item() == 0
            else:
                assert not td["is_init"][i, t + 1].item()
                assert torch.equal(td["observation"][i, t + 1], td["next", "observation"][i, t])
