"""Critic builders: keys, shapes, FSRL initialisation, input checks."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torch import nn

from s3rl_torchrl.modules import build_cost_qvalue_network, build_qvalue_network


def test_qvalue_network_keys_shape_and_concat_input():
    torch.manual_seed(0)
    critic = build_qvalue_network(5, 2, hidden=(8, 4))
    assert critic.in_keys == ["observation", "action"]
    assert critic.out_keys == ["state_action_value"]
    obs, act = torch.randn(3, 7, 5), torch.randn(3, 7, 2)
    out = critic(TensorDict({"observation": obs, "action": act}, [3, 7]))
    assert out["state_action_value"].shape == (3, 7, 1)
    # Q(s, a) = MLP(concat(s, a)): recompute with the layers by hand.
    linears = [m for m in critic.modules() if isinstance(m, nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(7, 8), (8, 4), (4, 1)]
    x = torch.cat([obs, act], -1)
    x = torch.relu(linears[0](x))
    x = torch.relu(linears[1](x))
    torch.testing.assert_close(out["state_action_value"], linears[2](x))


def test_orthogonal_weights_and_zero_biases():
    torch.manual_seed(0)
    critic = build_qvalue_network(17, 6, hidden=(128, 128), num_outputs=3)
    for layer in (m for m in critic.modules() if isinstance(m, nn.Linear)):
        w = layer.weight.detach()
        # Orthogonal (gain 1): orthonormal rows when out <= in, orthonormal columns otherwise.
        gram = w @ w.T if w.shape[0] <= w.shape[1] else w.T @ w
        torch.testing.assert_close(gram, torch.eye(gram.shape[0]), atol=1e-5, rtol=0)
        assert torch.count_nonzero(layer.bias) == 0


def test_cost_critic_output_key_and_independent_copies():
    torch.manual_seed(0)
    a, b = build_cost_qvalue_network(4, 2), build_cost_qvalue_network(4, 2)
    assert a.out_keys == ["state_action_cost_value"]
    td = TensorDict({"observation": torch.randn(5, 4), "action": torch.randn(5, 2)}, [5])
    assert a(td.clone())["state_action_cost_value"].shape == (5, 1)
    shared = {id(p) for p in a.parameters()} & {id(p) for p in b.parameters()}
    assert not shared
    assert not torch.equal(a.module[0].weight, b.module[0].weight)


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        ((0, 2), {}, "observation_dim"),
        ((3, -1), {}, "action_dim"),
        ((3, 2), {"hidden": (8, 0)}, "hidden"),
        ((3, 2), {"num_outputs": 0}, "num_outputs"),
    ],
)
def test_bad_sizes(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        build_qvalue_network(*args, **kwargs)
