"""``CostLabel`` in an env and on replay data, against ``safe = (cost <= threshold)``."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.envs import make_env
from s3rl_torchrl.transforms import CostLabel


def _transitions(costs: list[list[float]]) -> TensorDict:
    cost = torch.tensor(costs, dtype=torch.float32)
    return TensorDict(
        {"observation": torch.zeros(len(costs), 3), "next": {"cost": cost}}, batch_size=[len(costs)]
    )


def test_forward_labels_next_cost():
    td = CostLabel()(_transitions([[0.0], [1.0], [0.5], [0.0]]))
    assert td["next", "safe"].dtype == torch.bool
    assert td["next", "safe"].squeeze(-1).tolist() == [True, False, False, True]


def test_threshold_and_several_costs():
    td = CostLabel(threshold=0.5)(_transitions([[0.0], [1.0], [0.5]]))
    assert td["next", "safe"].squeeze(-1).tolist() == [True, False, True]
    td = CostLabel()(_transitions([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]]))
    assert td["next", "safe"].shape == (3, 1)
    assert td["next", "safe"].squeeze(-1).tolist() == [True, False, False]


def test_root_cost_without_next_and_missing_key():
    td = TensorDict({"cost": torch.tensor([[0.0], [2.0]])}, batch_size=[2])
    assert CostLabel()(td)["safe"].squeeze(-1).tolist() == [True, False]
    with pytest.raises(KeyError, match="no cost entry 'cost'"):
        CostLabel()(TensorDict({"reward": torch.zeros(2, 1)}, batch_size=[2]))


def test_in_env_step_and_reset():
    env = make_env("SafetyHalfCheetahVelocity-v1", seed=0, cost_threshold=0.0)
    spec = env.full_observation_spec["safe"]
    assert spec.dtype == torch.bool and spec.shape == (1,)
    reset = env.reset()
    assert reset["safe"].item() is True
    td = env.rollout(30, break_when_any_done=False)
    torch.testing.assert_close(td["next", "safe"], td["next", "cost"] == 0)
    assert td["next", "safe"].any() and (~td["next", "safe"]).any()


def test_batched_env_label_shape():
    env = make_env("SafetyHalfCheetahVelocity-v1", num_envs=3, seed=0, cost_threshold=0.0)
    td = env.rollout(5, break_when_any_done=False)
    assert td["next", "safe"].shape == td["next", "cost"].shape == (3, 5, 1)
    torch.testing.assert_close(td["next", "safe"], td["next", "cost"] == 0)


def test_replay_buffer_transform_labels_samples():
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10), batch_size=4, transform=CostLabel())
    rb.extend(_transitions([[0.0], [1.0], [0.0], [3.0]]))
    sample = rb.sample()
    torch.testing.assert_close(sample["next", "safe"], sample["next", "cost"] == 0)


def test_torchrl_keyword_spelling():
    # torchrl transforms take in_keys=/out_keys= lists; CostLabel accepts them as well.
    costs = [[0.0], [1.0], [0.5], [0.0]]
    label = CostLabel(in_keys=[("next", "cost")], out_keys=[("next", "safe")])
    assert label.in_keys == [("next", "cost")] and label.out_keys == [("next", "safe")]
    td = label(_transitions(costs))
    assert td["next", "safe"].squeeze(-1).tolist() == [True, False, False, True]
    # A single key and keyword threshold, as torchrl's own transforms allow.
    td = CostLabel(in_keys="cost", out_keys="unsafe_free", threshold=0.5)(_transitions(costs))
    assert td["next", "unsafe_free"].squeeze(-1).tolist() == [True, False, True, True]
    with pytest.raises(TypeError, match="in_key or in_keys, not both"):
        CostLabel(in_key="cost", in_keys=["cost"])
    with pytest.raises(ValueError, match="exactly one key"):
        CostLabel(in_keys=["cost", "cost2"])
