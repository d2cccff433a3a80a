"""The contrastive phase (``ContrastivePhase``): encoder-only InfoNCE steps on replay triplets."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded, LazyTensorStorage, TensorDictReplayBuffer
from torchrl.modules import MLP, ValueOperator
from torchrl.objectives import SoftUpdate

from s3rl_torchrl.algorithms import ContrastivePhase
from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import SafetyInfoNCELoss

# The actor of tests/modules/test_actor.py (5 observations, 3 bounded actions).
ACTION_SPEC = Bounded(torch.tensor([-1.0, 0.0, -3.0]), torch.tensor([1.0, 2.0, -1.0]), shape=(3,))


def make_actor(seed: int = 0, **kwargs):
    torch.manual_seed(seed)
    return build_s3rl_actor(5, ACTION_SPEC, **kwargs)


def make_critic(seed: int = 1) -> ValueOperator:
    torch.manual_seed(seed)
    return ValueOperator(
        MLP(in_features=8, out_features=1, num_cells=[32, 32]), in_keys=["observation", "action"]
    )

def separable_buffer(n: int = 400, seed: int = 0) -> TensorDictReplayBuffer:
    """Safe states around +1, unsafe around -1 in the first coordinate."""
    generator = torch.Generator().manual_seed(seed)
    safe = torch.rand(n, generator=generator) > 0.3
    obs = torch.randn(n, 5, generator=generator)
    obs[:, 0] += torch.where(safe, 1.0, -1.0)
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(n),
        sampler=SafeUnsafeSampler(),
        generator=torch.Generator().manual_seed(seed + 1),
    )
    rb.extend(TensorDict(observation=obs, next={"safe": safe[:, None]}, batch_size=[n]))
    return rb


def snapshot(module: nn.Module) -> dict[str, torch.Tensor]:
    return {name: p.detach().clone() for name, p in module.named_parameters()}


def test_phase_moves_only_the_encoder_and_lowers_the_loss():
    actor, critic = make_actor(hidden=(32, 32)), make_critic()
    encoder = get_policy_encoder(actor)
    encoder_names = {
        n for n, p in actor.named_parameters() if any(p is q for q in encoder.parameters())
    }
    view = SafeUnsafeSampler.contrastive_view(separable_buffer(), 32)
    loss = SafetyInfoNCELoss(encoder)
    phase = ContrastivePhase(loss, view, 1e-2, num_steps=30)
    fixed_batch = view.sample()
    before_loss = loss(fixed_batch)["loss_infonce"].item()
    actor_before, critic_before = snapshot(actor), snapshot(critic)

    stats = phase.run()

    after_loss = loss(fixed_batch)["loss_infonce"].item()
    assert after_loss < before_loss - 0.1
    actor_after = snapshot(actor)
    for name, value in actor_before.items():
        moved = not torch.equal(value, actor_after[name])
        assert moved == (name in encoder_names), name
    for name, value in snapshot(critic).items():
        assert torch.equal(value, critic_before[name]), name
    assert all(p.grad is None for p in actor.parameters())
    assert set(stats) == {
        "loss_infonce",
        "pos_similarity",
        "neg_similarity",
        "accuracy",
        "mi_lower_bound",
    }
    assert stats["mi_lower_bound"] == pytest.approx(math.log(33) - stats["loss_infonce"], rel=1e-5)
    assert phase.num_runs == 1 and phase.num_skipped == 0


def test_phase_skips_without_enough_unsafe_data():
    actor = make_actor(hidden=(16,))
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100), sampler=SafeUnsafeSampler())
    safe = torch.tensor([True] * 90 + [False] * 7)
    rb.extend(
        TensorDict(observation=torch.randn(97, 5), next={"safe": safe[:, None]}, batch_size=[97])
    )
    phase = ContrastivePhase(
        SafetyInfoNCELoss(get_policy_encoder(actor)), SafeUnsafeSampler.contrastive_view(rb, 8)
    )
    before = snapshot(actor)
    assert phase.run() is None
    assert phase.num_skipped == 1
    assert all(torch.equal(v, snapshot(actor)[k]) for k, v in before.items())
    rb.extend(
        TensorDict(
            observation=torch.randn(1, 5),
            next={"safe": torch.zeros(1, 1, dtype=bool)},
            batch_size=[1],
        )
    )
    assert phase.can_run()


def test_phase_state_dict_round_trip():
    actor = make_actor(hidden=(16,))
    view = SafeUnsafeSampler.contrastive_view(separable_buffer(), 8)
    phase = ContrastivePhase(SafetyInfoNCELoss(get_policy_encoder(actor)), view, 1e-3, num_steps=3)
    phase.run()
    state = phase.state_dict()
    fresh = ContrastivePhase(SafetyInfoNCELoss(get_policy_encoder(actor)), view, 1e-3, num_steps=3)
    fresh.load_state_dict(state)
    assert fresh.num_runs == 1
    steps = [s["step"].item() for s in fresh.optimizer.state_dict()["state"].values()]
    assert steps and all(step == 3 for step in steps)


def test_phase_rejects_foreign_parameters_and_bad_sources():
    actor = make_actor(hidden=(16,))
    loss = SafetyInfoNCELoss(get_policy_encoder(actor))
    rb = separable_buffer()
    view = SafeUnsafeSampler.contrastive_view(rb, 8)
    with pytest.raises(ValueError, match="encoder's parameters"):
        ContrastivePhase(loss, view, torch.optim.Adam(actor.parameters(), lr=1e-3))
    with pytest.raises(ValueError, match="contrastive_view"):
        ContrastivePhase(loss, rb)
    momentum = SafetyInfoNCELoss(get_policy_encoder(actor), momentum_encoder=True)
    with pytest.raises(ValueError, match="target_updater"):
        ContrastivePhase(momentum, view)


def test_phase_with_momentum_encoder_moves_targets():
    actor = make_actor(hidden=(16,))
    loss = SafetyInfoNCELoss(get_policy_encoder(actor), momentum_encoder=True)
    updater = SoftUpdate(loss, tau=0.5)
    view = SafeUnsafeSampler.contrastive_view(separable_buffer(), 8)
    phase = ContrastivePhase(loss, view, 1e-2, num_steps=2, target_updater=updater)
    target_before = loss.target_encoder_params.data.clone()
    phase.run()
    moved = [
        not torch.equal(target_before.get(k), loss.target_encoder_params.get(k))
        for k in target_before.keys(True, True)
    ]
    assert all(moved)


def test_end_to_end_on_env_data():
    from s3rl_torchrl.envs import make_env

    torch.manual_seed(0)
    env = make_env("SafetySwimmerVelocity-v1", seed=0)
    actor = build_s3rl_actor(
        env.observation_spec["observation"].shape[-1], env.action_spec, hidden=(32, 32)
    )
    with torch.no_grad():
        rollout = env.rollout(300, actor, break_when_any_done=False)
    env.close()
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(1000), sampler=SafeUnsafeSampler(), batch_size=64
    )
    rb.extend(rollout)
    view = SafeUnsafeSampler.contrastive_view(rb, 8)
    assert rb.sample()["observation"].shape == (64, 8)
    phase = ContrastivePhase(SafetyInfoNCELoss(get_policy_encoder(actor)), view, num_steps=2)
    num_unsafe = int((rollout["next", "cost"] > 0).sum())
    assert (rb.sampler.num_safe, rb.sampler.num_unsafe) == (300 - num_unsafe, num_unsafe)
    assert 8 <= num_unsafe <= 300 - 16  # this seed gives both kinds of states
    result = phase.run()
    assert result is not None and math.isfinite(result["loss_infonce"])
