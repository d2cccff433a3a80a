"""Graded InfoNCE (Rank-N-Contrast on Algorithm 4's candidates) against plain-Python loops."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded
from torchrl.modules import MLP, ValueOperator

from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import (
    GradedInfoNCELoss,
    SafetyInfoNCELoss,
    graded_infonce_loss,
    infonce_loss,
)
from tests.objectives._gradients import assert_momentum_encoder, assert_only_the_encoder_moves

FIXED_ANCHOR = torch.tensor([[1.0, 2.0, 0.5], [-0.3, 0.2, 1.0], [0.7, -1.1, 0.4]])
FIXED_POSITIVE = torch.tensor([[0.9, 1.5, 0.0], [0.1, 0.4, 0.8], [1.0, -0.2, 0.3]])
FIXED_NEGATIVE = torch.tensor([[-1.0, 0.3, 0.2], [0.2, -0.5, -1.0], [0.0, 1.0, -0.6]])
ANCHOR_LABEL = torch.tensor([0.0, 0.5, 2.0])
POSITIVE_LABEL = torch.tensor([0.1, 0.5, 1.0])
NEGATIVE_LABEL = torch.tensor([3.0, 0.4, 1.6])  # some negatives are closer than a positive


def reference_graded(anchor, positive, negative, ya, yp, yn, tau, positives):
    """Rank-N-Contrast on [p_i | n_1..n_M] in plain Python: per-anchor losses, |S| per term."""

    def unit(v):
        norm = math.sqrt(sum(x * x for x in v))
        return [x / norm for x in v]

    def dot(u, v):
        return sum(x * y for x, y in zip(u, v))

    anchor, positive, negative = (
        [unit(v) for v in t.tolist()] for t in (anchor, positive, negative)
    )
    losses, sizes = [], []
    for i, a in enumerate(anchor):
        candidates = [positive[i]] + negative
        labels = [float(yp[i])] + [float(y) for y in yn]
        logits = [dot(a, c) / tau for c in candidates]
        distance = [abs(y - float(ya[i])) for y in labels]
        turns = [0] if positives == "paired" else range(len(candidates))
        terms = []
        for j in turns:
            kept = [k for k in range(len(candidates)) if distance[k] >= distance[j]]
            log_denominator = math.log(sum(math.exp(logits[k]) for k in kept))
            terms.append(log_denominator - logits[j])
            sizes.append(len(kept))
        losses.append(sum(terms) / len(terms))
    return losses, sizes


@pytest.mark.parametrize("positives", ["paired", "all"])
@pytest.mark.parametrize("tau", [0.7, 0.1, 2.0])
def test_function_matches_plain_python(positives, tau):
    losses, _ = reference_graded(
        FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE,
        ANCHOR_LABEL, POSITIVE_LABEL, NEGATIVE_LABEL, tau, positives,
    )
    args = (FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ANCHOR_LABEL, POSITIVE_LABEL,
            NEGATIVE_LABEL, tau)
    got = graded_infonce_loss(*args, positives=positives, reduction="none")
    assert got.tolist() == pytest.approx(losses, rel=1e-5, abs=1e-6)
    mean = graded_infonce_loss(*args, positives=positives)
    assert mean.item() == pytest.approx(sum(losses) / 3, rel=1e-5)
    total = graded_infonce_loss(*args, positives=positives, reduction="sum")
    assert total.item() == pytest.approx(sum(losses), rel=1e-5)


def test_closed_form_closer_negative_leaves_the_denominator():
    # cos(a, p) = 1, cos(a, n1) = 0, cos(a, n2) = -1, tau = 0.5 -> logits [2, 0, -2].
    # Labels: anchor 0, positive 0.5, n1 0.2 (closer than the positive: not a negative),
    # n2 1.0. Paired: -log(e^2 / (e^2 + e^-2)) = log(1 + e^-4).
    anchor = torch.tensor([[3.0, 0.0]])
    positive = torch.tensor([[0.5, 0.0]])
    negative = torch.tensor([[0.0, 2.0], [-1.0, 0.0]])
    labels = (torch.tensor([0.0]), torch.tensor([0.5]), torch.tensor([0.2, 1.0]))
    loss = graded_infonce_loss(anchor, positive, negative, *labels, 0.5)
    assert loss.item() == pytest.approx(math.log(1.0 + math.exp(-4.0)), abs=1e-6)
    # All: j = p as above; j = n1 (d = 0.2): S = {p, n1, n2}; j = n2 (d = 1): S = {n2}.
    expected = (
        math.log(1.0 + math.exp(-4.0))
        + (math.log(math.exp(2) + 1 + math.exp(-2)) - 0.0)
        + 0.0
    ) / 3
    loss_all = graded_infonce_loss(anchor, positive, negative, *labels, 0.5, positives="all")
    assert loss_all.item() == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("tau", [0.7, 0.2])
def test_paired_form_equals_binary_infonce_on_two_label_values(tau):
    # Binary-labelled triplets: anchors and positives share one value, negatives the other
    # (either way round, any two values).
    for safe, unsafe in ((0.0, 1.0), (2.5, -1.0)):
        ya = torch.full((3,), safe)
        yn = torch.full((3,), unsafe)
        graded = graded_infonce_loss(
            FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ya, ya.clone(), yn, tau,
            reduction="none",
        )
        binary = infonce_loss(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, tau, reduction="none")
        torch.testing.assert_close(graded, binary)


def test_function_input_errors():
    args = (FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ANCHOR_LABEL, POSITIVE_LABEL)
    with pytest.raises(ValueError, match="labels"):
        graded_infonce_loss(*args, NEGATIVE_LABEL[:2])
    with pytest.raises(ValueError, match="positives"):
        graded_infonce_loss(*args, NEGATIVE_LABEL, positives="some")
    with pytest.raises(ValueError, match="reduction"):
        graded_infonce_loss(*args, NEGATIVE_LABEL, reduction="max")
    with pytest.raises(ValueError, match="temperature"):
        graded_infonce_loss(*args, NEGATIVE_LABEL, 0.0)


# ---------------------------------------------------------------- the LossModule
def identity_encoder(dim: int = 3, out_key: str = "embedding") -> TensorDictModule:
    linear = nn.Linear(dim, dim, bias=False)
    with torch.no_grad():
        linear.weight.copy_(torch.eye(dim))
    return TensorDictModule(linear, in_keys=["observation"], out_keys=[out_key])


def graded_batch(anchor, positive, negative, ya, yp, yn, shuffle=False, key="cost_to_go"):
    B = anchor.shape[0]
    observation = torch.cat([anchor, positive, negative])
    label = torch.cat([ya, yp, yn])[:, None]
    role = torch.arange(3).repeat_interleave(B)
    if shuffle:  # roles decide, not positions (pair order kept)
        order = torch.stack([torch.arange(B), torch.arange(B) + B, torch.arange(B) + 2 * B], -1)
        order = order.reshape(-1)
        observation, role, label = observation[order], role[order], label[order]
    return TensorDict(
        {"observation": observation, "contrastive_role": role, "next": {key: label}},
        batch_size=[observation.shape[0]],
    )


@pytest.mark.parametrize("positives", ["paired", "all"])
@pytest.mark.parametrize("shuffle", [False, True])
def test_module_matches_reference_with_diagnostics(positives, shuffle):
    tau = 0.7
    loss_module = GradedInfoNCELoss(identity_encoder(), temperature=tau, positives=positives)
    batch = graded_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ANCHOR_LABEL,
                         POSITIVE_LABEL, NEGATIVE_LABEL, shuffle)
    out = loss_module(batch)
    losses, sizes = reference_graded(
        FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE,
        ANCHOR_LABEL, POSITIVE_LABEL, NEGATIVE_LABEL, tau, positives,
    )
    loss = sum(losses) / 3
    assert out["loss_infonce"].item() == pytest.approx(loss, rel=1e-5)
    mean_log_size = sum(math.log(s) for s in sizes) / len(sizes)
    assert out["mi_lower_bound"].item() == pytest.approx(mean_log_size - loss, rel=1e-5)
    # similarities and accuracy by hand
    unit = torch.nn.functional.normalize
    a, p, n = unit(FIXED_ANCHOR, dim=-1), unit(FIXED_POSITIVE, dim=-1), unit(FIXED_NEGATIVE, dim=-1)
    pos = [float(a[i] @ p[i]) for i in range(3)]
    neg = [[float(a[i] @ n[m]) for m in range(3)] for i in range(3)]
    assert out["pos_similarity"].item() == pytest.approx(sum(pos) / 3, rel=1e-5)
    assert out["neg_similarity"].item() == pytest.approx(sum(map(sum, neg)) / 9, rel=1e-5)
    wins = []
    for i in range(3):
        d_pos = abs(float(POSITIVE_LABEL[i] - ANCHOR_LABEL[i]))
        rivals = [neg[i][m] for m in range(3)
                  if abs(float(NEGATIVE_LABEL[m] - ANCHOR_LABEL[i])) >= d_pos]
        wins.append(all(pos[i] > r for r in rivals))
    assert out["accuracy"].item() == pytest.approx(sum(wins) / 3)


def test_module_equals_binary_module_on_two_label_values():
    ya, yn = torch.zeros(3), torch.ones(3)
    batch = graded_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ya, ya.clone(), yn)
    graded = GradedInfoNCELoss(identity_encoder())(batch)
    binary = SafetyInfoNCELoss(identity_encoder())(batch)
    for key in binary.keys():
        assert graded[key].item() == pytest.approx(binary[key].item(), rel=1e-6), key


def test_renamed_label_key_and_in_keys():
    loss_module = GradedInfoNCELoss(identity_encoder())
    assert loss_module.in_keys == ["observation", "contrastive_role", ("next", "cost_to_go")]
    loss_module.set_keys(label=("next", "margin"))
    batch = graded_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ANCHOR_LABEL,
                         POSITIVE_LABEL, NEGATIVE_LABEL, key="margin")
    losses, _ = reference_graded(
        FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE,
        ANCHOR_LABEL, POSITIVE_LABEL, NEGATIVE_LABEL, 0.7, "paired",
    )
    assert loss_module(batch)["loss_infonce"].item() == pytest.approx(sum(losses) / 3, rel=1e-5)
    with pytest.raises(KeyError, match="margin"):
        loss_module(batch.exclude(("next", "margin")))


@pytest.mark.parametrize("positives", ["paired", "all"])
def test_gradients_reach_only_the_policy_encoder(positives):
    torch.manual_seed(0)
    spec = Bounded(-torch.ones(2), torch.ones(2), shape=(2,))
    actor = build_s3rl_actor(4, spec, hidden=(16, 8))
    critic = ValueOperator(
        MLP(in_features=6, out_features=1, num_cells=[16]), in_keys=["observation", "action"]
    )
    encoder = get_policy_encoder(actor)
    loss_module = GradedInfoNCELoss(encoder, positives=positives)
    labels = torch.rand(15)
    batch = graded_batch(torch.randn(5, 4), torch.randn(5, 4), torch.randn(5, 4),
                         labels[:5], labels[5:10], labels[10:])
    assert_only_the_encoder_moves(loss_module, batch, actor, critic, encoder)


def test_momentum_encoder_gradient_through_anchors_only_and_soft_update():
    torch.manual_seed(0)
    encoder = TensorDictModule(nn.Linear(3, 4), in_keys=["observation"], out_keys=["embedding"])
    loss_module = GradedInfoNCELoss(encoder, momentum_encoder=True)
    batch = graded_batch(FIXED_ANCHOR, FIXED_POSITIVE, FIXED_NEGATIVE, ANCHOR_LABEL,
                         POSITIVE_LABEL, NEGATIVE_LABEL)
    labels = (ANCHOR_LABEL, POSITIVE_LABEL, NEGATIVE_LABEL)
    assert_momentum_encoder(
        loss_module, encoder, batch, lambda za, zp, zn: graded_infonce_loss(za, zp, zn, *labels, 0.7)
    )


def test_module_input_errors():
    with pytest.raises(ValueError, match="positives"):
        GradedInfoNCELoss(identity_encoder(), positives="nearest")
    with pytest.raises(TypeError, match="TensorDictModule"):
        GradedInfoNCELoss(nn.Linear(3, 3))
