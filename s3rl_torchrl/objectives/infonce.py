"""Safety InfoNCE (paper §3.3, eq. 9, Algorithm 4) as a function and as a TorchRL ``LossModule``.

For anchors ``z_a`` and positives ``z_p`` (safe states) and negatives ``z_n`` (unsafe states),
L2-normalised so that dot products are cosine similarities:

    logits_i = [ z_a_i . z_p_i | z_a_i . z_n_1, ..., z_a_i . z_n_M ] / tau
    L        = mean_i  cross_entropy(logits_i, target=0)
    I(Z; L) >= log(M + 1) - L

The ``M`` negatives are shared by all anchors (``S_neg = Z_a Z_n^T``), as in Algorithm 4 where
``M = B``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase, TensorDictParams
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.objectives.common import LossModule

from s3rl_torchrl.data.sampler import ANCHOR, CONTRASTIVE_ROLE_KEY, NEGATIVE, POSITIVE

__all__ = ["infonce_logits", "infonce_loss", "SafetyInfoNCELoss"]

_REDUCTIONS = ("mean", "sum", "none")


def _check_temperature(temperature: float) -> float:
    temperature = float(temperature)
    if not (temperature > 0.0 and math.isfinite(temperature)):
        raise ValueError(f"temperature must be a positive finite number, got {temperature}.")
    return temperature


def infonce_logits(
    anchor: torch.Tensor,
    positive: torch.Tensor,
    negative: torch.Tensor,
    temperature: float | torch.Tensor = 0.7,
    *,
    normalize: bool = True,
) -> torch.Tensor:
    """The InfoNCE logits ``[S_pos | S_neg] / tau`` of Algorithm 4, shape ``[B, 1 + M]``.

    Args:
        anchor: ``[B, d]`` anchor embeddings.
        positive: ``[B, d]`` positive embeddings, ``positive[i]`` paired with ``anchor[i]``.
        negative: ``[M, d]`` negative embeddings, shared by every anchor.
        temperature: ``tau > 0``.
        normalize: L2-normalise the embeddings first (cosine similarity, the paper's ``g``).
    """
    if anchor.ndim != 2 or positive.shape != anchor.shape:
        raise ValueError(
            "infonce: anchor and positive must both be [B, d] with the same shape, got "
            f"{tuple(anchor.shape)} and {tuple(positive.shape)}."
        )
    if negative.ndim != 2 or negative.shape[-1] != anchor.shape[-1]:
        raise ValueError(
            f"infonce: negative must be [M, d] with d = {anchor.shape[-1]} (shared by every "
            f"anchor), got {tuple(negative.shape)}."
        )
    if not isinstance(temperature, torch.Tensor):
        temperature = _check_temperature(temperature)
    if normalize:
        anchor = F.normalize(anchor, dim=-1)
        positive = F.normalize(positive, dim=-1)
        negative = F.normalize(negative, dim=-1)
    positive_logit = (anchor * positive).sum(-1, keepdim=True)
    negative_logits = anchor @ negative.T
    return torch.cat([positive_logit, negative_logits], dim=-1) / temperature


def infonce_loss(
    anchor: torch.Tensor,
    positive: torch.Tensor,
    negative: torch.Tensor,
    temperature: float | torch.Tensor = 0.7,
    *,
    normalize: bool = True,
    reduction: Literal["mean", "sum", "none"] = "mean",
) -> torch.Tensor:
    """InfoNCE loss of Algorithm 4: cross-entropy of :func:`infonce_logits` with target 0.

    Shapes as in :func:`infonce_logits`; ``reduction="none"`` gives the ``[B]`` per-anchor loss.
    """
    if reduction not in _REDUCTIONS:
        raise ValueError(f"reduction must be one of {_REDUCTIONS}, got {reduction!r}.")
    logits = infonce_logits(anchor, positive, negative, temperature, normalize=normalize)
    target = torch.zeros(logits.shape[0], dtype=torch.long, device=logits.device)
    return F.cross_entropy(logits, target, reduction=reduction)


class SafetyInfoNCELoss(LossModule):
    """Contrastive loss that separates safe from unsafe states in an encoder's embedding.

    The forward takes a batch from a contrastive :class:`~s3rl_torchrl.data.SafeUnsafeSampler`
    (``B`` anchors, ``B`` positives, ``B`` negatives marked by ``"contrastive_role"`` 0/1/2; the
    ``i``-th anchor is paired with the ``i``-th positive), encodes the observations with
    ``encoder``, L2-normalises the embeddings and computes Algorithm 4 of the paper.

    Args:
        encoder (TensorDictModule): reads the observation key(s) (its ``in_keys``) and writes the
            embedding (``tensor_keys.embedding``, default ``"embedding"``), e.g.
            :func:`~s3rl_torchrl.modules.get_policy_encoder` of the S3RL actor. Its parameters
            are the actor's own: the loss does not copy them.
        temperature (float): ``tau``. Defaults to 0.7 (paper).

    Keyword Args:
        momentum_encoder (bool): encode positives and negatives with a target copy of the
            encoder (no gradient) updated by :class:`~torchrl.objectives.SoftUpdate`
            (MoCo style); anchors use the online encoder. Defaults to ``False`` (Algorithm 4:
            one encoder, gradient through all three).
        reduction (str): ``"mean"`` (default, the paper's), ``"sum"`` or ``"none"``
            (per-anchor loss).

    Returns, from :meth:`forward`, a TensorDict with

    * ``loss_infonce``: the loss (differentiable);
    * ``pos_similarity``: mean cosine similarity of the anchor-positive pairs;
    * ``neg_similarity``: mean cosine similarity over all ``B x B`` anchor-negative pairs (the
      paper's ``mu_pos`` / ``mu_neg`` are these divided by ``tau``);
    * ``accuracy``: fraction of anchors whose positive logit strictly beats every negative one;
    * ``mi_lower_bound``: ``log(B + 1) - loss``, the InfoNCE bound on ``I(Z; L)`` in nats.

    Examples:
        >>> loss = SafetyInfoNCELoss(get_policy_encoder(actor))
        >>> out = loss(contrastive_view.sample())
        >>> out["loss_infonce"].backward()
    """

    @dataclass
    class _AcceptedKeys:
        """Configurable tensordict keys (see :meth:`set_keys`).

        Attributes:
            embedding (NestedKey): the encoder output used as the embedding.
                Defaults to ``"embedding"``.
            contrastive_role (NestedKey): integer role per transition, 0 anchor, 1 positive,
                2 negative. Defaults to ``"contrastive_role"``.
        """

        embedding: NestedKey = "embedding"
        contrastive_role: NestedKey = CONTRASTIVE_ROLE_KEY

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys = ["loss_infonce", "pos_similarity", "neg_similarity", "accuracy", "mi_lower_bound"]

    encoder: TensorDictModule
    encoder_params: TensorDictParams
    target_encoder_params: TensorDictParams

    def __init__(
        self,
        encoder: TensorDictModule,
        temperature: float = 0.7,
        *,
        momentum_encoder: bool = False,
        reduction: Literal["mean", "sum", "none"] = "mean",
    ) -> None:
        if reduction not in _REDUCTIONS:
            raise ValueError(f"reduction must be one of {_REDUCTIONS}, got {reduction!r}.")
        if not hasattr(encoder, "in_keys") or not hasattr(encoder, "out_keys"):
            raise TypeError(
                "SafetyInfoNCELoss: encoder must be a TensorDictModule (observation -> "
                f"embedding), got {type(encoder).__name__}; see "
                "s3rl_torchrl.modules.get_policy_encoder."
            )
        super().__init__()
        self.momentum_encoder = bool(momentum_encoder)
        self.convert_to_functional(encoder, "encoder", create_target_params=self.momentum_encoder)
        self.register_buffer("temperature", torch.tensor(_check_temperature(temperature)))
        self.reduction = reduction

    @property
    def in_keys(self) -> list[NestedKey]:
        return [*self.encoder.in_keys, self.tensor_keys.contrastive_role]

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        pass

    def encoder_parameters(self) -> list[torch.nn.Parameter]:
        """The trainable parameters of the encoder (what a contrastive optimizer should own)."""
        return [p for p in self.encoder_params.values(True, True) if p.requires_grad]

    def _encode(self, observations: TensorDictBase, params: TensorDictBase) -> torch.Tensor:
        with params.to_module(self.encoder):
            return self.encoder(observations).get(self.tensor_keys.embedding)

    def _split_roles(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, ...]:
        if tensordict.ndim != 1:
            raise ValueError(
                f"SafetyInfoNCELoss expects a 1-D batch of 3B transitions, got batch size "
                f"{tuple(tensordict.batch_size)}."
            )
        role = tensordict.get(self.tensor_keys.contrastive_role, None)
        if role is None:
            raise KeyError(
                f"SafetyInfoNCELoss: no {self.tensor_keys.contrastive_role!r} entry in the batch; "
                "sample it with a contrastive SafeUnsafeSampler "
                "(SafeUnsafeSampler.contrastive_view(replay_buffer, B))."
            )
        role = role.reshape(tensordict.shape[0], -1)[:, 0]
        masks = tuple(role == r for r in (ANCHOR, POSITIVE, NEGATIVE))
        counts = [int(m.sum()) for m in masks]
        if counts[0] < 1 or counts[0] != counts[1] or counts[0] != counts[2]:
            raise ValueError(
                "SafetyInfoNCELoss: the batch needs B >= 1 anchors (role 0), B positives "
                f"(role 1) and B negatives (role 2); got {counts[0]}, {counts[1]}, {counts[2]}."
            )
        if counts[0] * 3 != role.numel():
            raise ValueError(
                f"SafetyInfoNCELoss: contrastive roles must be 0, 1 or 2, got values "
                f"{sorted(set(role.tolist()))}."
            )
        return masks

    def _embed_roles(
        self, tensordict: TensorDictBase
    ) -> tuple[tuple[torch.Tensor, ...], tuple[torch.Tensor, ...]]:
        """``(anchor, positive, negative)`` embeddings and the three role masks."""
        anchor_mask, positive_mask, negative_mask = self._split_roles(tensordict)
        observations = tensordict.select(*self.encoder.in_keys)
        if self.momentum_encoder:
            anchor = self._encode(observations[anchor_mask], self.encoder_params)
            with torch.no_grad():
                others = observations[~anchor_mask]
                # .data: swapping a TensorDictParams in and out of a module would turn the
                # target buffers into Parameters that require grad.
                embeddings = self._encode(others, self.target_encoder_params.data)
            is_positive = positive_mask[~anchor_mask]
            positive, negative = embeddings[is_positive], embeddings[~is_positive]
        else:
            embeddings = self._encode(observations, self.encoder_params)
            anchor = embeddings[anchor_mask]
            positive = embeddings[positive_mask]
            negative = embeddings[negative_mask]
        return (anchor, positive, negative), (anchor_mask, positive_mask, negative_mask)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        (anchor, positive, negative), _ = self._embed_roles(tensordict)
        logits = infonce_logits(anchor, positive, negative, self.temperature)
        target = torch.zeros(logits.shape[0], dtype=torch.long, device=logits.device)
        per_anchor = F.cross_entropy(logits, target, reduction="none")
        loss = self._reduce_loss(per_anchor, reduction=self.reduction)
        diagnostics = self._diagnostics(
            logits, per_anchor, rivals=logits[:, 1:], log_candidates=math.log(logits.shape[-1])
        )
        return TensorDict({"loss_infonce": loss, **diagnostics}, batch_size=[])

    @torch.no_grad()
    def _diagnostics(
        self,
        logits: torch.Tensor,
        per_anchor: torch.Tensor,
        rivals: torch.Tensor,
        log_candidates: float | torch.Tensor,
    ) -> dict[str, torch.Tensor]:
        """Cosine similarities of the positives and negatives, how often the positive beats
        every rival, and the InfoNCE bound ``log(candidates) - loss`` on the mutual
        information."""
        cosine = logits * self.temperature
        return {
            "pos_similarity": cosine[:, 0].mean(),
            "neg_similarity": cosine[:, 1:].mean(),
            "accuracy": (logits[:, 0] > rivals.amax(-1)).float().mean(),
            "mi_lower_bound": log_candidates - per_anchor.mean(),
        }
