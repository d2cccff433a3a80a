"""InfoNCE (Algorithm 4) against hand computations, and the ``SafetyInfoNCELoss`` module."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded, LazyTensorStorage, TensorDictReplayBuffer
from torchrl.modules import MLP, ValueOperator

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import SafetyInfoNCELoss, infonce_logits, infonce_loss
from tests.objectives._gradients import assert_momentum_encoder, assert_only_the_encoder_moves


def reference_infonce(anchor, positive, negative, tau):
    """Algorithm 4 in plain Python floats: per-anchor losses and the cosine similarities."""

    def unit(v):
        norm = math.sqrt(sum(x * x for x in v))
        return [x / norm for x in v]

    def dot(u, v):
        return sum(x * y for x, y in zip(u, v))

    anchor, positive, negative = (
        [unit(v) for v in t.tolist()] for t in (anchor, positive, negative)
    )
    losses, pos, neg = [], [], []
    for a, p in zip(anchor, positive):
        s_pos = dot(a, p)
        s_neg = [dot(a, n) for n in negative]
        logits = [s_pos / tau] + [s / tau for s in s_neg]
        log_denominator = math.log(sum(math.exp(x) for x in logits))
        losses.append(log_denominator - logits[0])
        pos.append(s_pos)
        neg.extend(s_neg)
    return losses, pos, neg


def test_closed_form_single_anchor():
    # cos(a, p) = 1, cos(a, n1) = 0, cos(a, n2) = -1, tau = 0.5 -> logits [2, 0, -2]
    anchor = torch.tensor([[3.0, 0.0]])
    positive = torch.tensor([[0.5, 0.0]])
    negative = torch.tensor([[0.0, 2.0], [-1.0, 0.0]])
    expected = math.log(1.0 + math.exp(-2.0) + math.exp(-4.0))
    loss = infonce_loss(anchor, positive, negative, 0.5)
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    logits = infonce_logits(anchor, positive, negative, 0.5)
    assert logits[0].tolist() == pytest.approx([2.0, 0.0, -2.0], abs=1e-6)


FIXED_ANCHOR = torch.tensor([[1.0, 2.0, 0.5], [-0.3, 0.2, 1.0], [0.7, -1.1, 0.4]])
FIXED_POSITIVE = torch.tensor([[0.9, 1.5, 0.0], [0.1, 0.4, 0.8], [1.0, -0.2, 0.3]])
FIXED_NEGATIVE = torch.tensor([[-1.0, 0.3, 0.2], [0.2, -0.5, -1.0], [0.0, 1.0, -0.6]])


@pytest.mark.parametrize("tau", [0.7, 0.1, 2.0])
def test_function_matches_plain_python_algorithm_4(tau):
    losses, _, _ = reference_infonce(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau)
    got = infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau, reduction="none")
    assert got.tolist() == pytest.approx(losses, rel=1e-5)
    mean = infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau)
    assert mean.item() == pytest.approx(sum(losses) / len(losses), rel=1e-5)
    total = infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau, reduction="sum")
    assert total.item() == pytest.approx(sum(losses), rel=1e-5)


def test_more_negatives_than_anchors():
    negative = torch.cat([FIXED_NEGATIVE, -FIXED_ANCHOR])  # M = 6, B = 3
    losses, _, _ = reference_infonce(FIXED_ANCHOR, FIXED_POSITIVE, negative, 0.7)
    got = infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, negative, 0.7, reduction="none")
    assert got.tolist() == pytest.approx(losses, rel=1e-5)


def test_cosine_ignores_scale_and_unnormalised_option_does_not():
    scaled = infonce_loss(5.0 * FIXED_ANCHOR, 0.1 * FIXED_POSITIVE, 3.0 * FIXED_NEGATIVE, 0.7)
    assert scaled.item() == pytest.approx(
        infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, 0.7).item(), rel=1e-5
    )
    raw = infonce_logits(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, 0.5, normalize=False)
    assert raw[0, 0].item() == pytest.approx((1.0 * 0.9 + 2.0 * 1.5) / 0.5, rel=1e-6)


def test_function_input_errors():
    with pytest.raises(ValueError, match="temperature"):
        infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, 0.0)
    with pytest.raises(ValueError, match="anchor and positive"):
        infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE[:2], FIXED_NEGATIVE)
    with pytest.raises(ValueError, match="negative"):
        infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE[:, :2])
    with pytest.raises(ValueError, match="reduction"):
        infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, reduction="max")


# ---------------------------------------------------------------- the LossModule
def identity_encoder(dim: int = 3, out_key: str = "embedding") -> TensorDictModule:
    linear = nn.Linear(dim, dim, bias=False)
    with torch.no_grad():
        linear.weight.copy_(torch.eye(dim))
    return TensorDictModule(linear, in_keys=["observation"], out_keys=[out_key])


def triplet_batch(anchor, positive, negative, shuffle: bool = False) -> TensorDict:
    B = anchor.shape[0]
    observation = torch.cat([anchor, positive, negative])
    role = torch.arange(3).repeat_interleave(B)
    if shuffle:  # roles decide, not positions: interleave while keeping pair order
        order = torch.stack([torch.arange(B), torch.arange(B) + B, torch.arange(B) + 2 * B], -1)
        order = order.reshape(-1)
        observation, role = observation[order], role[order]
    return TensorDict(
        {"observation": observation, "contrastive_role": role}, batch_size=[observation.shape[0]]
    )


@pytest.mark.parametrize("shuffle", [False, True])
def test_module_matches_reference_with_diagnostics(shuffle):
    tau = 0.7
    loss_module = SafetyInfoNCELoss(identity_encoder(), temperature=tau)
    out = loss_module(triplet_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, shuffle))
    losses, pos, neg = reference_infonce(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau)
    loss = sum(losses) / 3
    assert out["loss_infonce"].item() == pytest.approx(loss, rel=1e-5)
    assert out["pos_similarity"].item() == pytest.approx(sum(pos) / 3, rel=1e-5)
    assert out["neg_similarity"].item() == pytest.approx(sum(neg) / 9, rel=1e-5)
    assert out["mi_lower_bound"].item() == pytest.approx(math.log(4) - loss, rel=1e-5)
    # accuracy by hand: does the positive beat every negative, anchor by anchor?
    wins = [pos[i] > max(neg[3 * i : 3 * i + 3]) for i in range(3)]
    assert out["accuracy"].item() == pytest.approx(sum(wins) / 3)
    assert not any(k.startswith("loss_") for k in out.keys() if k != "loss_infonce")


def test_accuracy_counts_ties_as_misses():
    anchor = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    positive = torch.tensor([[1.0, 0.0], [1.0, 0.0]])
    negative = torch.tensor([[2.0, 0.0], [-1.0, 0.0]])  # ties anchor 0; beats anchor 1's positive
    out = SafetyInfoNCELoss(identity_encoder(2))(triplet_batch(anchor, positive, negative))
    assert out["accuracy"].item() == 0.0


def test_renamed_embedding_key():
    loss_module = SafetyInfoNCELoss(identity_encoder(out_key="z"))
    loss_module.set_keys(embedding="z")
    out = loss_module(triplet_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE))
    losses, _, _ = reference_infonce(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, 0.7)
    assert out["loss_infonce"].item() == pytest.approx(sum(losses) / 3, rel=1e-5)
    assert loss_module.in_keys == ["observation", "contrastive_role"]


def test_gradients_reach_only_the_policy_encoder():
    torch.manual_seed(0)
    spec = Bounded(-torch.ones(2), torch.ones(2), shape=(2,))
    actor = build_s3rl_actor(4, spec, hidden=(16, 8))
    critic = ValueOperator(
        MLP(in_features=6, out_features=1, num_cells=[16]), in_keys=["observation", "action"]
    )
    encoder = get_policy_encoder(actor)
    loss_module = SafetyInfoNCELoss(encoder)
    batch = triplet_batch(torch.randn(5, 4), torch.randn(5, 4), torch.randn(5, 4))
    assert_only_the_encoder_moves(loss_module, batch, actor, critic, encoder)


def test_momentum_encoder_targets_and_soft_update():
    # With the target equal to the online encoder, the value is the plain loss; only the anchors
    # carry a gradient.
    torch.manual_seed(0)
    encoder = TensorDictModule(nn.Linear(3, 4), in_keys=["observation"], out_keys=["embedding"])
    loss_module = SafetyInfoNCELoss(encoder, momentum_encoder=True)
    batch = triplet_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE)
    assert_momentum_encoder(
        loss_module, encoder, batch, lambda za, zp, zn: infonce_loss(za, zp, zn, 0.7)
    )


def test_module_works_on_sampler_batches():
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(64), sampler=SafeUnsafeSampler())
    safe = torch.tensor([i % 2 == 0 for i in range(64)])
    rb.extend(
        TensorDict(
            {"observation": torch.randn(64, 3), "next": {"safe": safe[:, None]}}, batch_size=[64]
        )
    )
    view = SafeUnsafeSampler.contrastive_view(rb, 8)
    batch = view.sample()
    out = SafetyInfoNCELoss(identity_encoder())(batch)
    obs = batch["observation"]
    losses, _, _ = reference_infonce(obs[:8], obs[8:16], obs[16:], 0.7)
    assert out["loss_infonce"].item() == pytest.approx(sum(losses) / 8, rel=1e-5)


def test_module_input_errors():
    with pytest.raises(ValueError, match="temperature"):
        SafetyInfoNCELoss(identity_encoder(), temperature=-1.0)
    with pytest.raises(TypeError, match="TensorDictModule"):
        SafetyInfoNCELoss(nn.Linear(3, 3))
    loss_module = SafetyInfoNCELoss(identity_encoder())
    batch = triplet_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE)
    with pytest.raises(KeyError, match="contrastive_role"):
        loss_module(batch.exclude("contrastive_role"))
    with pytest.raises(ValueError, match="anchors"):
        loss_module(batch[:8])
    bad_role = batch.clone()
    bad_role["contrastive_role"][0] = 5
    with pytest.raises(ValueError):
        loss_module(bad_role)
