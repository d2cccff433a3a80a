"""Graded InfoNCE: the S3RL contrastive loss for a graded safety label, in Rank-N-Contrast form.

Follows Rank-N-Contrast (Zha, Cao, Yang, Gu, Zhou, Hua, Li, Ma, Wang and Jia, "Rank-N-Contrast:
Learning Continuous Representations for Regression", NeurIPS 2023, eq. 2): for an anchor ``i``
and a positive ``j``, the negatives are the samples whose label is at least as far from the
anchor's as ``j``'s,

    l(i, j) = - log  exp(s_ij / tau) / sum_{k in S_ij} exp(s_ik / tau),
    S_ij    = { k : |y_i - y_k| >= |y_i - y_j| }        (j itself included),

so that the embedding similarity is taught to fall as the label distance grows. It is applied
to the batch layout of Algorithm 4 (paper §3.3): anchor ``i`` sees the candidates
``C_i = [p_i | n_1 .. n_M]`` (its paired positive, then the ``M`` negatives shared by every
anchor), ``s`` is the cosine similarity.

* ``positives="paired"`` (default): only ``j = p_i`` is a positive. The loss is Algorithm 4 with
  one change, the denominator drops the candidates whose label is *closer* to the anchor's than
  the positive's (they are not negatives). When the label takes two values and the positives
  share the anchors' value while the negatives do not (a binary-labelled triplet batch),
  every ``S_i`` is all of ``C_i`` and the loss **equals** :func:`~s3rl_torchrl.objectives.
  infonce_loss`.
* ``positives="all"``: every candidate takes its turn as ``j`` (Rank-N-Contrast proper,
  ``mean_j l(i, j)`` per anchor), which also orders the negatives among themselves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey

from s3rl_torchrl.data.sampler import CONTRASTIVE_ROLE_KEY
from s3rl_torchrl.objectives.infonce import _REDUCTIONS, SafetyInfoNCELoss, infonce_logits
from s3rl_torchrl.transforms.cost_to_go import COST_TO_GO_KEY

__all__ = ["GradedInfoNCELoss", "graded_infonce_loss", "GRADED_POSITIVES"]

GRADED_POSITIVES = ("paired", "all")


def _check_labels(anchor_label, positive_label, negative_label, batch: int, negatives: int):
    shapes = (anchor_label.shape, positive_label.shape, negative_label.shape)
    if shapes != ((batch,), (batch,), (negatives,)):
        raise ValueError(
            f"graded infonce: labels must be [B], [B], [M] = [{batch}], [{batch}], "
            f"[{negatives}], got {[tuple(s) for s in shapes]}."
        )


def _graded_terms(
    logits: torch.Tensor,
    anchor_label: torch.Tensor,
    candidate_label: torch.Tensor,
    positives: str,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-anchor losses ``[B]``, the denominator masks and their sizes.

    ``logits`` and ``candidate_label`` are ``[B, C]`` (column 0 the paired positive).
    Returns ``(per_anchor, mask, size)``: for ``"paired"`` ``mask`` is ``[B, C]`` (``S_i``) and
    ``size`` ``[B]``; for ``"all"`` ``mask`` is ``[B, C, C]`` (``S_ij`` over the last dim) and
    ``size`` ``[B, C]``.
    """
    distance = (candidate_label - anchor_label[:, None]).abs()
    if positives == "paired":
        mask = distance >= distance[:, :1]
        log_denominator = logits.masked_fill(~mask, -math.inf).logsumexp(-1)
        return log_denominator - logits[:, 0], mask, mask.sum(-1)
    mask = distance[:, None, :] >= distance[:, :, None]  # [i, j, k]: k in S_ij
    expanded = logits[:, None, :].expand(mask.shape)
    log_denominator = expanded.masked_fill(~mask, -math.inf).logsumexp(-1)  # [B, C]
    return (log_denominator - logits).mean(-1), mask, mask.sum(-1)


def graded_infonce_loss(
    anchor: torch.Tensor,
    positive: torch.Tensor,
    negative: torch.Tensor,
    anchor_label: torch.Tensor,
    positive_label: torch.Tensor,
    negative_label: torch.Tensor,
    temperature: float | torch.Tensor = 0.7,
    *,
    positives: Literal["paired", "all"] = "paired",
    normalize: bool = True,
    reduction: Literal["mean", "sum", "none"] = "mean",
) -> torch.Tensor:
    """Rank-N-Contrast on Algorithm 4's candidates (module docstring).

    Args:
        anchor, positive: ``[B, d]`` embeddings, ``positive[i]`` paired with ``anchor[i]``.
        negative: ``[M, d]`` embeddings shared by every anchor.
        anchor_label, positive_label: ``[B]`` graded labels; negative_label: ``[M]``.
        temperature: ``tau > 0``.
        positives: ``"paired"`` (the paired positive only) or ``"all"`` (every candidate).
        normalize: L2-normalise the embeddings (cosine similarity).
        reduction: ``"mean"``, ``"sum"`` or ``"none"`` (``[B]`` per-anchor losses).
    """
    if reduction not in _REDUCTIONS:
        raise ValueError(f"reduction must be one of {_REDUCTIONS}, got {reduction!r}.")
    if positives not in GRADED_POSITIVES:
        raise ValueError(f"positives must be one of {GRADED_POSITIVES}, got {positives!r}.")
    logits = infonce_logits(anchor, positive, negative, temperature, normalize=normalize)
    _check_labels(
        anchor_label, positive_label, negative_label, anchor.shape[0], negative.shape[0]
    )
    candidate_label = torch.cat(
        [positive_label[:, None], negative_label[None, :].expand(anchor.shape[0], -1)], -1
    )
    per_anchor, _, _ = _graded_terms(logits, anchor_label, candidate_label, positives)
    if reduction == "none":
        return per_anchor
    return per_anchor.mean() if reduction == "mean" else per_anchor.sum()


class GradedInfoNCELoss(SafetyInfoNCELoss):
    """Contrastive loss that orders an encoder's embeddings by a graded safety label.

    The interface of :class:`~s3rl_torchrl.objectives.SafetyInfoNCELoss` (same batch layout,
    encoder handling, momentum encoder, reduction and outputs), with the label of every
    transition read from the batch (``tensor_keys.label``, default ``("next", "cost_to_go")``
    written by :class:`~s3rl_torchrl.transforms.CostToGo`; ``("next", "margin")`` for a task's
    margin) and the loss of :func:`graded_infonce_loss`. Sample its batches with a graded
    :class:`~s3rl_torchrl.data.SafeUnsafeSampler` (``bin_edges=``): anchors and positives from
    one label bin, negatives from the others.

    Args:
        encoder (TensorDictModule): observation -> embedding (the actor's policy encoder).
        temperature (float): ``tau``. Defaults to 0.7 (the paper's, for the binary loss).

    Keyword Args:
        positives (str): ``"paired"`` (default; equals Algorithm 4 on binary labels) or
            ``"all"`` (Rank-N-Contrast over every candidate).
        momentum_encoder (bool), reduction (str): as for ``SafetyInfoNCELoss``.

    Returns, from :meth:`forward`, a TensorDict with

    * ``loss_infonce``: the loss (differentiable; the key of the binary loss, so that the
      contrastive phase and the logs take either);
    * ``pos_similarity``, ``neg_similarity``: as for the binary loss;
    * ``accuracy``: fraction of anchors whose positive logit strictly beats every other
      candidate of its denominator ``S_i`` (every negative, on binary labels);
    * ``mi_lower_bound``: ``mean_i log |S_i| - loss`` (``positives="all"``: the mean over the
      ``(i, j)`` terms of ``log |S_ij|``, minus the loss); ``log(B + 1) - loss`` on binary
      labels, the binary loss's bound.
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable tensordict keys (see :meth:`set_keys`).

        Attributes:
            embedding (NestedKey): the encoder output. Defaults to ``"embedding"``.
            contrastive_role (NestedKey): 0 anchor, 1 positive, 2 negative.
                Defaults to ``"contrastive_role"``.
            label (NestedKey): the graded label of each transition (one float).
                Defaults to ``("next", "cost_to_go")``.
        """

        embedding: NestedKey = "embedding"
        contrastive_role: NestedKey = CONTRASTIVE_ROLE_KEY
        label: NestedKey = COST_TO_GO_KEY

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys

    def __init__(
        self,
        encoder: TensorDictModule,
        temperature: float = 0.7,
        *,
        positives: Literal["paired", "all"] = "paired",
        momentum_encoder: bool = False,
        reduction: Literal["mean", "sum", "none"] = "mean",
    ) -> None:
        if positives not in GRADED_POSITIVES:
            raise ValueError(f"positives must be one of {GRADED_POSITIVES}, got {positives!r}.")
        super().__init__(
            encoder, temperature, momentum_encoder=momentum_encoder, reduction=reduction
        )
        self.positives = positives

    @property
    def in_keys(self) -> list[NestedKey]:
        return [*super().in_keys, self.tensor_keys.label]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        label = tensordict.get(self.tensor_keys.label, None)
        if label is None:
            raise KeyError(
                f"GradedInfoNCELoss: no label entry {self.tensor_keys.label!r} in the batch; "
                "label the transitions (s3rl_torchrl.transforms.CostToGo, or make_env(..., "
                "margin=True)) or set_keys(label=...)."
            )
        (anchor, positive, negative), masks = self._embed_roles(tensordict)
        label = label.reshape(tensordict.shape[0], -1)[:, 0].to(anchor.dtype)
        anchor_label, positive_label, negative_label = (label[m] for m in masks)
        logits = infonce_logits(anchor, positive, negative, self.temperature)
        candidate_label = torch.cat(
            [positive_label[:, None], negative_label[None, :].expand(anchor.shape[0], -1)], -1
        )
        per_anchor, mask, size = _graded_terms(
            logits, anchor_label, candidate_label, self.positives
        )
        loss = self._reduce_loss(per_anchor, reduction=self.reduction)
        # The positive's rivals are the candidates left in its denominator.
        paired_mask = mask if self.positives == "paired" else mask[:, 0, :]
        with torch.no_grad():
            rivals = logits[:, 1:].masked_fill(~paired_mask[:, 1:], -math.inf)
        diagnostics = self._diagnostics(
            logits, per_anchor, rivals=rivals, log_candidates=size.float().log().mean()
        )
        return TensorDict({"loss_infonce": loss, **diagnostics}, batch_size=[])
