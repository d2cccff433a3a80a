"""The S3RL actor (encoder + Gaussian head) and its use by torchrl's SACLoss (the contrastive
phase on its encoder: tests/trainer/test_contrastive.py)."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded, Unbounded
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate

from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder

LOW = torch.tensor([-1.0, 0.0, -3.0])
HIGH = torch.tensor([1.0, 2.0, -1.0])


def action_spec() -> Bounded:
    return Bounded(LOW, HIGH, shape=(3,))


def make_actor(seed: int = 0, **kwargs):
    torch.manual_seed(seed)
    return build_s3rl_actor(5, action_spec(), **kwargs)


def make_critic(seed: int = 1) -> ValueOperator:
    torch.manual_seed(seed)
    return ValueOperator(
        MLP(in_features=8, out_features=1, num_cells=[32, 32]), in_keys=["observation", "action"]
    )


def linear_layers(module: nn.Module) -> list[nn.Linear]:
    return [m for m in module.modules() if isinstance(m, nn.Linear)]


# ---------------------------------------------------------------- the actor
def test_structure_keys_and_bounds():
    actor = make_actor()
    td = actor(TensorDict(observation=10 * torch.randn(500, 5), batch_size=[500]))
    assert td["embedding"].shape == (500, 128)
    assert td["action"].shape == (500, 3)
    assert ((td["action"] >= LOW) & (td["action"] <= HIGH)).all()
    assert actor.log_prob_keys[0] in td.keys()
    assert td[actor.log_prob_keys[0]].shape == (500,)
    sizes = [(m.in_features, m.out_features) for m in linear_layers(actor)]
    assert sizes == [(5, 128), (128, 128), (128, 3), (128, 3)]


def test_deterministic_action_matches_the_formula():
    actor = make_actor(hidden=(16, 8))
    enc1, enc2, mu, log_std = linear_layers(actor)
    with torch.no_grad():  # non-zero biases so that they are exercised too
        for layer in (enc1, enc2, mu, log_std):
            layer.bias.uniform_(-0.5, 0.5)
    obs = torch.randn(7, 5)
    z = torch.relu(enc2(torch.relu(enc1(obs))))
    loc = torch.tanh(mu(z))  # bounded mean (unbounded=False)
    expected = LOW + (torch.tanh(loc) + 1) / 2 * (HIGH - LOW)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        td = actor(TensorDict(observation=obs, batch_size=[7]))
    torch.testing.assert_close(td["embedding"], z)
    torch.testing.assert_close(td["action"], expected, rtol=1e-5, atol=1e-5)


def test_unbounded_mean_and_log_std_clamp():
    actor = make_actor(hidden=(8,), unbounded=True, log_std_bounds=(-3.0, 0.5))
    _, mu, log_std = linear_layers(actor)
    with torch.no_grad():
        mu.weight.fill_(1.0)
        log_std.weight.zero_()
        log_std.bias.copy_(torch.tensor([-10.0, 0.0, 10.0]))
    obs = torch.full((4, 5), 3.0)
    td = actor(TensorDict(observation=obs, batch_size=[4]))
    z = td["embedding"]
    torch.testing.assert_close(td["loc"], z.sum(-1, keepdim=True).expand(4, 3))
    assert td["loc"].abs().max() > 1  # not squashed
    torch.testing.assert_close(td["scale"][0], torch.tensor([math.exp(-3.0), 1.0, math.exp(0.5)]))


def test_orthogonal_init_and_zero_bias():
    for layer in linear_layers(make_actor()):
        w = layer.weight
        gram = w @ w.T if w.shape[0] <= w.shape[1] else w.T @ w
        torch.testing.assert_close(gram, torch.eye(gram.shape[0]), atol=1e-4, rtol=0)
        assert not layer.bias.any()


def test_stochastic_actions_are_sampled_by_default():
    actor = make_actor()
    obs = TensorDict(observation=torch.zeros(2, 5), batch_size=[2])
    first, second = actor(obs.clone())["action"], actor(obs.clone())["action"]
    assert not torch.equal(first, second)


def test_encoder_accessor_shares_parameters():
    actor = make_actor()
    encoder = get_policy_encoder(actor)
    assert encoder.in_keys == ["observation"] and encoder.out_keys == ["embedding"]
    actor_params = {id(p) for p in actor.parameters()}
    assert {id(p) for p in encoder.parameters()} <= actor_params
    assert sum(p.numel() for p in encoder.parameters()) == 5 * 128 + 128 + 128 * 128 + 128
    obs = TensorDict(observation=torch.randn(3, 5), batch_size=[3])
    torch.testing.assert_close(encoder(obs.clone())["embedding"], actor(obs.clone())["embedding"])
    with pytest.raises(ValueError, match="PolicyEncoder"):
        get_policy_encoder(make_critic())


def test_builder_input_errors():
    with pytest.raises(ValueError, match="hidden"):
        build_s3rl_actor(5, action_spec(), hidden=())
    with pytest.raises(ValueError, match="log_std_bounds"):
        build_s3rl_actor(5, action_spec(), log_std_bounds=(2.0, -2.0))
    with pytest.raises(TypeError, match="bounded"):
        build_s3rl_actor(5, Unbounded(shape=(3,)))
    with pytest.raises(ValueError, match="high > low"):
        build_s3rl_actor(5, Bounded(HIGH, LOW, shape=(3,)))


def test_batched_env_spec_is_reduced_to_one_env():
    batched = Bounded(LOW.expand(4, 3), HIGH.expand(4, 3), shape=(4, 3))
    actor = build_s3rl_actor(5, batched)
    td = actor(TensorDict(observation=torch.randn(4, 5), batch_size=[4]))
    assert td["action"].shape == (4, 3)
    assert ((td["action"] >= LOW) & (td["action"] <= HIGH)).all()
    uneven = Bounded(torch.stack([LOW, LOW - 1]), torch.stack([HIGH, HIGH]), shape=(2, 3))
    with pytest.raises(ValueError, match="per env"):
        build_s3rl_actor(5, uneven)


def test_sac_loss_out_of_the_box():
    actor, critic = make_actor(), make_critic()
    loss = SACLoss(actor, critic, num_qvalue_nets=2, action_spec=action_spec())
    loss.make_value_estimator(gamma=0.99)
    SoftUpdate(loss, tau=0.05)
    n = 16
    batch = TensorDict(
        observation=torch.randn(n, 5),
        action=LOW + torch.rand(n, 3) * (HIGH - LOW),
        next=TensorDict(
            observation=torch.randn(n, 5),
            reward=torch.randn(n, 1),
            done=torch.zeros(n, 1, dtype=torch.bool),
            terminated=torch.zeros(n, 1, dtype=torch.bool),
        ),
        batch_size=[n],
    )
    out = loss(batch)
    assert loss.tensor_keys.log_prob == actor.log_prob_keys[0]
    assert {"loss_actor", "loss_qvalue", "loss_alpha"} <= set(out.keys())
    out["loss_actor"].backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in actor.parameters())


# ---------------------------------------------------------------- the contrastive phase
