"""``ContrastivePhase``: the periodic encoder-only InfoNCE phase of S3RL (paper §3.4, Alg. 3).

Every ``T`` gradient steps of the RL algorithm (paper: ``enc_update_steps = 1000``) the trainer
calls :meth:`ContrastivePhase.run`, which takes ``E`` InfoNCE steps (``enc_training_epoch =
50``) with an optimizer that owns the policy encoder's parameters only: the actor head and the
critics are not in the loss graph and not in the optimizer, so they stay frozen.

Every family takes the phase alike, on its actor's policy encoder
(:func:`build_contrastive_phase`), sampling triplets from the buffer the sampler of
:func:`contrastive_sampler` partitions by the contrasted label.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import ReplayBuffer, TensorDictReplayBuffer
from torchrl.objectives import SoftUpdate

from s3rl_torchrl.algorithms.config import ContrastiveConfig
from s3rl_torchrl.data.sampler import SafeUnsafeSampler
from s3rl_torchrl.modules import get_policy_encoder
from s3rl_torchrl.objectives.graded_infonce import GradedInfoNCELoss
from s3rl_torchrl.objectives.infonce import SafetyInfoNCELoss
from s3rl_torchrl.objectives.target_update import ForeachSoftUpdate
from s3rl_torchrl.transforms import COST_TO_GO_KEY

__all__ = [
    "DEFAULT_LABEL_BINS",
    "LABEL_KEYS",
    "SAFE_LABEL_KEY",
    "ContrastivePhase",
    "build_contrastive_phase",
    "contrastive_sampler",
    "label_bins",
]

# The binary safety label (CostLabel): the paper's contrastive phase and the binary probe.
SAFE_LABEL_KEY: NestedKey = ("next", "safe")
# Where each label of ContrastiveConfig.label is stored.
LABEL_KEYS: dict[str, NestedKey] = {
    "binary": SAFE_LABEL_KEY,
    "cost_to_go": COST_TO_GO_KEY,
    "margin": ("next", "margin"),
}
# The bins (sampler strata) of a graded label when contrastive_cfg.label_bins is null, in the
# label's units. cost_to_go (gamma_c = 0.9, one cost per violating step): no cost in sight
# (< 0.05: the next cost is ~30 or more steps away), a cost ahead, in or next to a violation
# (>= 1), a sustained violation (>= 4). margin: violating (< 0), close to the limit, nearer
# than 1, farther (metres for the Goal tasks, the speed's units for the velocity tasks).
DEFAULT_LABEL_BINS = {"cost_to_go": (0.05, 1.0, 4.0), "margin": (0.0, 0.5, 1.0)}


def label_bins(cfg: ContrastiveConfig, label: str) -> tuple[float, ...]:
    """The bins of a graded label: ``cfg.label_bins``, else the label's default."""
    return DEFAULT_LABEL_BINS[label] if cfg.label_bins is None else tuple(cfg.label_bins)


class ContrastivePhase:
    """Runs ``num_steps`` InfoNCE updates of the policy encoder, or skips when data is lacking.

    Args:
        loss: the :class:`~s3rl_torchrl.objectives.SafetyInfoNCELoss` (or its graded subclass
            :class:`~s3rl_torchrl.objectives.GradedInfoNCELoss`) built on the policy encoder.
        source: a replay buffer whose samples are contrastive triplet batches, normally
            ``SafeUnsafeSampler.contrastive_view(main_buffer, B)``. Its ``can_sample()`` decides
            the skip (paper, Algorithm 2: fewer than ``B`` unsafe or ``2B`` safe transitions).
        optimizer: a ``torch.optim.Optimizer`` over (a subset of) ``loss.encoder_parameters()``,
            or a learning rate for a new Adam over them. Defaults to ``5e-4`` (the paper's
            actor learning rate; the paper gives no separate encoder rate).
        num_steps: InfoNCE steps per phase (``E``). Defaults to 50 (paper).

    Keyword Args:
        target_updater: a :class:`~torchrl.objectives.SoftUpdate` on ``loss`` when the loss uses
            a momentum encoder; stepped after every optimizer step.
        max_grad_norm: clip the encoder gradient norm to this value when given.

    Examples:
        >>> view = SafeUnsafeSampler.contrastive_view(replay_buffer, 256)
        >>> phase = ContrastivePhase(SafetyInfoNCELoss(get_policy_encoder(actor)), view, 5e-4)
        >>> if step % 1000 == 0:
        ...     stats = phase.run()   # None when skipped
    """

    def __init__(
        self,
        loss: SafetyInfoNCELoss,
        source: ReplayBuffer,
        optimizer: torch.optim.Optimizer | float = 5e-4,
        num_steps: int = 50,
        *,
        target_updater: SoftUpdate | None = None,
        max_grad_norm: float | None = None,
    ) -> None:
        if not isinstance(loss, SafetyInfoNCELoss):
            raise TypeError(f"loss must be a SafetyInfoNCELoss, got {type(loss).__name__}.")
        if not (hasattr(source, "sample") and hasattr(source, "can_sample")):
            raise TypeError(
                "source must be a replay buffer of contrastive batches, e.g. "
                f"SafeUnsafeSampler.contrastive_view(replay_buffer, B); got {type(source).__name__}."
            )
        sampler = getattr(source, "sampler", None)
        if isinstance(sampler, SafeUnsafeSampler) and not sampler.contrastive:
            raise ValueError(
                "source samples ordinary batches (its SafeUnsafeSampler is not contrastive); pass "
                "SafeUnsafeSampler.contrastive_view(replay_buffer, B) instead."
            )
        if int(num_steps) < 1:
            raise ValueError(f"num_steps must be >= 1, got {num_steps}.")
        if loss.momentum_encoder and target_updater is None:
            raise ValueError(
                "the loss has a momentum encoder: pass target_updater=SoftUpdate(loss, tau=...) "
                "so that it follows the online encoder."
            )
        self.loss = loss
        self.source = source
        self.num_steps = int(num_steps)
        self.target_updater = target_updater
        self.max_grad_norm = max_grad_norm
        self._parameters = loss.encoder_parameters()
        if isinstance(optimizer, torch.optim.Optimizer):
            self._check_optimizer(optimizer)
            self.optimizer = optimizer
        else:
            lr = float(optimizer)
            if not lr > 0:
                raise ValueError(f"the learning rate must be > 0, got {lr}.")
            self.optimizer = torch.optim.Adam(self._parameters, lr=lr)
        self.num_runs = 0
        self.num_skipped = 0

    def _check_optimizer(self, optimizer: torch.optim.Optimizer) -> None:
        allowed = {id(p) for p in self._parameters}
        foreign = [
            tuple(p.shape)
            for group in optimizer.param_groups
            for p in group["params"]
            if id(p) not in allowed
        ]
        if foreign:
            raise ValueError(
                "the contrastive optimizer may only own the policy encoder's parameters "
                "(loss.encoder_parameters()); it also holds parameters of shapes "
                f"{foreign}, which would let the phase move the actor head or the critics."
            )

    def can_run(self) -> bool:
        """Whether the source holds enough safe and unsafe transitions for one batch."""
        return bool(self.source.can_sample())

    def run(self) -> dict[str, float] | None:
        """Take ``num_steps`` InfoNCE steps; ``None`` (and nothing changes) when it must skip.

        Returns the mean over the steps of every entry of the loss output (``loss_infonce``,
        ``pos_similarity``, ``neg_similarity``, ``accuracy``, ``mi_lower_bound``), as floats.
        """
        if not self.can_run():
            self.num_skipped += 1
            return None
        totals: dict[str, float] = {}
        for _ in range(self.num_steps):
            out = self.loss(self.source.sample())
            self.optimizer.zero_grad(set_to_none=True)
            loss_value = out["loss_infonce"]
            # reduction="none" gives per-anchor losses; step on their mean.
            (loss_value.mean() if loss_value.ndim else loss_value).backward()
            if self.max_grad_norm is not None:
                torch.nn.utils.clip_grad_norm_(self._parameters, self.max_grad_norm)
            self.optimizer.step()
            if self.target_updater is not None:
                self.target_updater.step()
            for key, value in out.items():
                totals[key] = totals.get(key, 0.0) + float(value.detach().mean())
        # The encoder is also the actor's trunk: leave no stale gradient for the RL optimizer.
        self.optimizer.zero_grad(set_to_none=True)
        self.num_runs += 1
        return {key: total / self.num_steps for key, total in totals.items()}

    def state_dict(self) -> dict[str, Any]:
        return {
            "optimizer": self.optimizer.state_dict(),
            "num_runs": self.num_runs,
            "num_skipped": self.num_skipped,
        }

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self.optimizer.load_state_dict(state_dict["optimizer"])
        self.num_runs = int(state_dict["num_runs"])
        self.num_skipped = int(state_dict["num_skipped"])


def contrastive_sampler(cfg: ContrastiveConfig, contrastive: bool) -> SafeUnsafeSampler:
    """The sampler partitions the buffer by the label the contrastive phase contrasts: safe /
    unsafe (also without the phase), or the bins of a graded label."""
    if not contrastive or not cfg.graded:
        return SafeUnsafeSampler(SAFE_LABEL_KEY)
    return SafeUnsafeSampler(LABEL_KEYS[cfg.label], bin_edges=label_bins(cfg, cfg.label))


def build_contrastive_phase(
    cfg: ContrastiveConfig, actor: TensorDictModuleBase, labelled: TensorDictReplayBuffer
) -> ContrastivePhase:
    """S3RL's phase on the actor's policy encoder, sampling triplets from ``labelled`` (the
    replay buffer, or the on-policy FIFO of recent labelled states)."""
    encoder = get_policy_encoder(actor)
    momentum = cfg.momentum_tau is not None
    if cfg.graded:
        infonce = GradedInfoNCELoss(
            encoder, temperature=cfg.temperature, positives=cfg.positives, momentum_encoder=momentum
        )
        infonce.set_keys(label=LABEL_KEYS[cfg.label])
    else:
        infonce = SafetyInfoNCELoss(encoder, temperature=cfg.temperature, momentum_encoder=momentum)
    view = SafeUnsafeSampler.contrastive_view(labelled, cfg.batch_size)
    updater = ForeachSoftUpdate(infonce, tau=cfg.momentum_tau) if momentum else None
    return ContrastivePhase(infonce, view, cfg.lr, num_steps=cfg.steps, target_updater=updater)
