"""episode_statistics and evaluate against hand-built rollouts: each env copy of a
``[num_envs, T]`` rollout gives its first episode, up to its first ``("next", "done")``; what
follows a reset inside the rollout is not counted (cut by the rollout, or whole only because it
was short)."""

import torch
from tensordict import TensorDict

from s3rl_torchrl.trainer.evaluation import episode_statistics, evaluate


def _rollout(rewards, costs, dones) -> TensorDict:
    rewards, costs = torch.tensor(rewards, dtype=torch.float32), torch.tensor(costs)
    dones = torch.tensor(dones, dtype=torch.bool)
    n, t = rewards.shape
    return TensorDict(
        {
            "next": {
                "reward": rewards.unsqueeze(-1),
                "cost": costs.float().unsqueeze(-1),
                "done": dones.unsqueeze(-1),
            }
        },
        batch_size=[n, t],
    )


def test_each_copy_gives_its_first_episode_only():
    # Env 0 falls after 2 steps; the rollout then runs 4 steps of a new episode and ends: that
    # remainder is not an episode. Env 1 ends two episodes; the second fitted in the rollout
    # only because the first was short, so it is not counted either.
    rollout = _rollout(
        rewards=[[1, 2, 3, 4, 5, 6], [1, 1, 1, 2, 2, 2]],
        costs=[[0, 1, 0, 0, 0, 0], [1, 0, 0, 0, 1, 1]],
        dones=[[0, 1, 0, 0, 0, 0], [0, 0, 1, 0, 0, 1]],
    )
    assert episode_statistics(rollout) == [(3.0, 1.0, 2, 1), (3.0, 1.0, 3, 2)]


def test_an_episode_longer_than_the_rollout_is_kept_cut_at_its_end():
    # max_steps shorter than the task's episode: the first episode is cut, and it is the
    # only measure of the policy such a rollout gives.
    rollout = _rollout(rewards=[[1, 1, 1, 1]], costs=[[0, 0, 1, 1]], dones=[[0, 0, 0, 0]])
    assert episode_statistics(rollout) == [(4.0, 2.0, 4, 2)]


class _FallingEnv:
    """Each rollout: a fall after 3 steps, then a remainder the rollout cuts at 5 steps."""

    def __init__(self):
        self.calls = 0

    def rollout(self, max_steps, policy, break_when_any_done):
        assert not break_when_any_done
        self.calls += 1
        return _rollout(
            rewards=[[1.0] * max_steps],
            costs=[[1, 1, 1, 0, 0]],
            dones=[[0, 0, 1, 0, 0]],
        )


def test_evaluate_rolls_out_until_it_has_whole_episodes():
    env = _FallingEnv()
    result = evaluate(env, policy=None, episodes=3, max_steps=5)
    assert env.calls == 3  # one whole episode per rollout, not two
    assert result.episode_lengths == [3, 3, 3]
    assert result.episode_costs == [3.0, 3.0, 3.0]
    assert result.reward_mean == 3.0 and result.cost_mean == 3.0
    assert result.safe_occupancy == 0.0


def test_episode_sums_are_float64_as_python_summed_them():
    # float32 per-step rewards that a float32 sum rounds: 1e8 + 1 + 1 - 1e8 is 0 in float32,
    # 2 in float64 (the per-step values themselves are exact in float32).
    rollout = _rollout(rewards=[[1e8, 1.0, 1.0, -1e8]], costs=[[0, 0, 0, 0]], dones=[[0, 0, 0, 1]])
    assert sum([1e8, 1.0, 1.0, -1e8]) == 2.0
    assert episode_statistics(rollout) == [(2.0, 0.0, 4, 4)]
