"""What every algorithm family's config shares, and the checks every config uses.

Each family (``sac.py``, ``ddpg.py``, ``ppo.py``) subclasses :class:`AlgoConfig` (or
:class:`OffPolicyConfig`) with its own fields only; ``trainer/config.py`` puts the family's
class under ``TrainConfig.algo``, and Hydra type-checks each ``configs/algo/*.yaml`` against
it. Types are checked by OmegaConf when Hydra composes the config; values (ranges, choices) by
``check``, which names the field and what it accepts.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

from omegaconf import MISSING

from s3rl_torchrl.objectives.graded_infonce import GRADED_POSITIVES
from s3rl_torchrl.objectives.lagrangian import LAGRANGIAN_CADENCES

LAGRANGIAN_CHOICES = ("pid", "learned", "none")
# The contrastive phase's safety label (docs/representation.md): the paper's binary safe/unsafe
# label, the discounted cost-to-go (transforms.CostToGo) or the task's margin (TaskSpec).
CONTRASTIVE_LABELS = ("binary", "cost_to_go", "margin")
# Where in each interval of T gradient steps the contrastive phase runs (ContrastiveConfig.phase_at).
PHASE_POSITIONS = ("start", "end")


class ConfigError(ValueError):
    """A configuration value is out of range or not one of its choices."""


def fail(path: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"Invalid value {value!r} for '{path}': {allowed}.")


def check_finite(obj: Any, path: str) -> None:
    """Every float field of a config (nested dataclasses included) is a finite number: NaN
    passes every range check (its comparisons are all false) and would fail deep inside."""
    for f in fields(obj):
        value, name = getattr(obj, f.name), f"{path}.{f.name}" if path else f.name
        if is_dataclass(value):
            check_finite(value, name)
        elif isinstance(value, float) and not math.isfinite(value):
            fail(name, value, "must be a finite number")


def check_choice(path: str, value: Any, choices: tuple) -> None:
    if value not in choices:
        fail(path, value, "allowed values are " + ", ".join(map(str, choices)))


def check_range(
    path: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_inclusive: bool = True,
) -> None:
    below = low is not None and (value < low if low_inclusive else value <= low)
    above = high is not None and value > high
    if below or above:
        lo = "(-inf" if low is None else ("[" if low_inclusive else "(") + f"{low}"
        hi = "inf)" if high is None else f"{high}]"
        fail(path, value, f"must be in {lo}, {hi}")


def check_positive(path: str, value: float) -> None:
    check_range(path, value, 0.0, low_inclusive=False)


@dataclass(frozen=True)
class RemovedOption:
    """An ``algo`` option that left the package: ``default``, the value under which it changed
    nothing (every config now runs as that value did), and ``last_commit``, the last commit
    that had it (to re-run what used another value)."""

    default: Any
    last_commit: str
    what: str


#: The ``algo`` options that left the package because no committed result chose them
#: (research/2026-11-28-options-removed.md says what each gave). A saved config (a run's
#: ``config.json``, a checkpoint's) may still hold them: :func:`drop_removed_options`.
REMOVED_OPTIONS: dict[str, RemovedOption] = {
    "cost_gamma": RemovedOption(
        None, "6c13fe3", "the SAC family's cost critics' own discount (null: gamma)"
    ),
}


def drop_removed_options(algo: dict[str, Any], path: str = "algo") -> dict[str, Any]:
    """A saved ``algo`` without the :data:`REMOVED_OPTIONS` it holds at their default (the run
    ran as every run does now). One at another value raises ``ConfigError``: that run used what
    the package no longer has, so it cannot be resumed or rebuilt as it was."""
    for name, option in REMOVED_OPTIONS.items():
        if name in algo and algo[name] != option.default:
            raise ConfigError(
                f"'{path}.{name}' is {json.dumps(algo[name])}, but {name} ({option.what}) has "
                f"been removed: only its default, {json.dumps(option.default)}, loads. Use the "
                f"package at commit {option.last_commit}, the last that had it, for this run."
            )
    return {key: value for key, value in algo.items() if key not in REMOVED_OPTIONS}


@dataclass
class PIDConfig:
    """PID Lagrangian gains and the OmniSafe/rlpyt options (off by default: FSRL's form)."""

    kp: float = 0.05
    ki: float = 0.0005
    kd: float = 0.1
    ema_alpha: float = 0.0  # 0 disables the EMA of error and cost (FSRL)
    derivative_delay: int = 1
    ki_inside_integral: bool = False
    penalty_max: float | None = None
    # The derivative's cost history starts at the limit (FSRL: e_prev = 0) or at 0 (OmniSafe).
    derivative_history_init: str = "limit"

    def check(self, path: str) -> None:
        check_choice(
            f"{path}.derivative_history_init", self.derivative_history_init, ("limit", "zero")
        )
        for name in ("kp", "ki", "kd"):
            check_range(f"{path}.{name}", getattr(self, name), 0.0)
        check_range(f"{path}.ema_alpha", self.ema_alpha, 0.0, 1.0)
        check_range(f"{path}.derivative_delay", self.derivative_delay, 1)
        if self.penalty_max is not None:
            check_positive(f"{path}.penalty_max", self.penalty_max)


@dataclass
class ContrastiveConfig:
    """The S3RL representation phase (paper §3.4, Table 3)."""

    temperature: float = 0.7
    batch_size: int = 64  # B: B anchors, B positives, B negatives per InfoNCE step
    update_interval: int = 1000  # T: gradient steps between phases (enc_update_steps)
    steps: int = 50  # E: InfoNCE steps per phase (enc_training_epoch)
    # Where in each interval the phase runs. "start": after the interval's first gradient step,
    # so the actor head (frozen during the phase) takes T - 1 steps on the moved encoder before
    # the interval ends. "end": after its last step, the runs before 2026-11-28: where an epoch
    # ended on a multiple of T gradient steps (experiment=paper; SafetyCarCircle-v0 under
    # experiment=safe), every evaluation, checkpoint and the final policy came right after a
    # phase (docs/representation.md, "Where in its interval a phase runs"). One phase per T
    # steps either way.
    phase_at: str = "start"
    lr: float = 5e-4
    momentum_tau: float | None = None  # MoCo-style target encoder when set
    # The safety label the phase contrasts: "binary" (the paper's, SafetyInfoNCELoss),
    # "cost_to_go" or "margin" (graded: GradedInfoNCELoss, triplets drawn by label bin).
    label: str = "binary"
    label_gamma: float = 0.9  # cost_to_go's gamma_c (horizon ~ 1 / (1 - gamma_c) steps)
    # Inner edges of the graded label's bins (the sampler's strata); None: the label's default
    # (algorithms.contrastive.DEFAULT_LABEL_BINS), in the label's units.
    label_bins: list[float] | None = None
    positives: str = "paired"  # graded loss: "paired" (Algorithm 4's pairs) or "all" (RnC)

    @property
    def graded(self) -> bool:
        return self.label != "binary"

    def phase_due(self, grad_steps: int) -> bool:
        """Whether a phase runs after gradient step ``grad_steps`` (counted from 1): one per T
        steps from the first full interval on, after step T + 1, 2T + 1, ... (``start``) or
        after step T, 2T, ... (``end``)."""
        T = self.update_interval
        offset = 1 if self.phase_at == "start" else 0
        return grad_steps >= T and (grad_steps - offset) % T == 0

    def check(self, path: str) -> None:
        check_positive(f"{path}.temperature", self.temperature)
        check_range(f"{path}.batch_size", self.batch_size, 1)
        check_range(f"{path}.update_interval", self.update_interval, 1)
        check_range(f"{path}.steps", self.steps, 1)
        check_positive(f"{path}.lr", self.lr)
        if self.momentum_tau is not None:
            check_range(f"{path}.momentum_tau", self.momentum_tau, 0.0, 1.0, low_inclusive=False)
        check_choice(f"{path}.label", self.label, CONTRASTIVE_LABELS)
        check_choice(f"{path}.phase_at", self.phase_at, PHASE_POSITIONS)
        check_choice(f"{path}.positives", self.positives, GRADED_POSITIVES)
        if not 0.0 <= self.label_gamma < 1.0:
            fail(f"{path}.label_gamma", self.label_gamma, "must be in [0.0, 1.0)")
        if self.label_bins is not None:
            edges = list(self.label_bins)
            increasing = all(a < b for a, b in zip(edges, edges[1:]))
            if not edges or not increasing or len(edges) > 126:
                fail(
                    f"{path}.label_bins",
                    edges,
                    "must be null or 1 to 126 strictly increasing bin edges",
                )


@dataclass
class AlgoConfig:
    """What every family has: its name, the Lagrangian, the contrastive phase, the discount,
    the learning rates of actor and critics, the (mini)batch and the buffer.

    A family's config subclasses it with its own fields (``SACConfig``, ``DDPGConfig``,
    ``PPOConfig``); ``name`` is an entry of ``algorithms.registry.ALGORITHMS``, which gives
    ``lagrangian`` and ``contrastive`` their value for that algorithm.
    """

    name: str = MISSING
    lagrangian: str = "pid"
    contrastive: bool = False
    pid: PIDConfig = field(default_factory=PIDConfig)
    lagrangian_lr: float = 5e-3  # learned Lagrangian only: Adam's rate per update
    lagrangian_init: float = 0.0
    # When lambda updates (objectives.LagrangianUpdater, docs/objectives.md): "collect" (FSRL,
    # the paper: once per collect, from its finished episodes) or "step" (OmniSafe: after every
    # gradient step, from the last lagrangian_window finished episodes). Gains and rates are
    # per update, so each cadence needs its own (configs/pid/, configs/experiment/).
    lagrangian_cadence: str = "collect"
    lagrangian_window: int = 10  # episodes (cadence=step; OmniSafe's window_lens)
    lagrangian_warmup_frames: int = 0  # lambda stays at lagrangian_init until past these frames
    # Upper bound of the learned multiplier (OmniSafe's lagrangian_upper_bound); None: none.
    # The PID controller has its own (pid.penalty_max).
    lagrangian_max: float | None = None
    # What the controller aims at, for the policy a run delivers (docs/objectives.md, "Aiming at
    # the delivered policy"): the fraction of task.cost_limit it holds J at (1.0: the limit)...
    lagrangian_target: float = 1.0
    # ...and J itself: 0 follows the training (stochastic) episodes alone; K > 0 follows, per
    # cost, the larger of that and the mean cost of the last K deterministic evaluation episodes.
    lagrangian_eval_window: int = 0
    rescaling: bool = True  # divide the actor loss by 1 + lambda (FSRL, paper)
    gamma: float = 0.99
    actor_lr: float = 5e-4
    critic_lr: float = 1e-3
    batch_size: int = 256  # off-policy: the replay batch; PPO: the minibatch
    # Off-policy: the replay buffer. PPO family: the FIFO of recent labelled states that the
    # contrastive phase and the linear probe sample (docs/representation.md).
    buffer_size: int = 100_000
    # Gradient steps per collected frame. Read by the off-policy schedule only (the on-policy
    # one owes ppo_epochs passes per collect); it is here, not in OffPolicyConfig, because the
    # experiment presets (quick, tiny) set it for whichever algorithm runs.
    update_per_step: float = 0.2
    contrastive_cfg: ContrastiveConfig = field(default_factory=ContrastiveConfig)

    def check(self, path: str) -> None:
        check_choice(f"{path}.lagrangian", self.lagrangian, LAGRANGIAN_CHOICES)
        self.pid.check(f"{path}.pid")
        self.contrastive_cfg.check(f"{path}.contrastive_cfg")
        check_positive(f"{path}.lagrangian_lr", self.lagrangian_lr)
        check_range(f"{path}.lagrangian_init", self.lagrangian_init, 0.0)
        check_choice(f"{path}.lagrangian_cadence", self.lagrangian_cadence, LAGRANGIAN_CADENCES)
        check_range(f"{path}.lagrangian_window", self.lagrangian_window, 1)
        check_range(f"{path}.lagrangian_warmup_frames", self.lagrangian_warmup_frames, 0)
        check_range(f"{path}.lagrangian_target", self.lagrangian_target, 0.0, 1.0, low_inclusive=False)
        check_range(f"{path}.lagrangian_eval_window", self.lagrangian_eval_window, 0)
        if self.lagrangian_max is not None:
            check_positive(f"{path}.lagrangian_max", self.lagrangian_max)
            if self.lagrangian != "learned":
                fail(
                    f"{path}.lagrangian_max",
                    self.lagrangian_max,
                    f"bounds the learned multiplier only (algo.lagrangian={self.lagrangian!r}); "
                    "the PID's bound is algo.pid.penalty_max",
                )
        check_range(f"{path}.gamma", self.gamma, 0.0, 1.0)
        for name in ("actor_lr", "critic_lr"):
            check_positive(f"{path}.{name}", getattr(self, name))
        check_range(f"{path}.batch_size", self.batch_size, 1)
        check_range(f"{path}.buffer_size", self.buffer_size, self.batch_size)
        check_positive(f"{path}.update_per_step", self.update_per_step)


@dataclass
class OffPolicyConfig(AlgoConfig):
    """The off-policy families (SAC, DDPG): n-step returns from a replay buffer, target
    networks moved by ``tau``."""

    tau: float = 0.05
    n_step: int = 2

    def check(self, path: str) -> None:
        super().check(path)
        check_range(f"{path}.tau", self.tau, 0.0, 1.0, low_inclusive=False)
        check_range(f"{path}.n_step", self.n_step, 1)
