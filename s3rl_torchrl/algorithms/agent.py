"""What every algorithm family builds and the trainer runs: an :class:`Agent`, and the
:class:`Family` record that says how (its config class, its update schedule, its builder).

A family's module (``sac.py``, ``ddpg.py``, ``ppo.py``) builds the actor, critics, loss,
optimisers and gradient step from its config and a :class:`Networks`; the Lagrangian and the
contrastive phase, which every family takes alike, are added by :func:`build_agent`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.tensor_specs import TensorSpec
from torchrl.objectives import LossModule

from s3rl_torchrl.algorithms.config import AlgoConfig
from s3rl_torchrl.algorithms.contrastive import ContrastivePhase, build_contrastive_phase
from s3rl_torchrl.algorithms.schedule import UpdateSchedule
from s3rl_torchrl.modules import ACTIVATIONS, build_s3rl_actor
from s3rl_torchrl.objectives import (
    LagrangianController,
    LagrangianUpdater,
    LearnedLagrangian,
    PIDLagrangian,
)

__all__ = [
    "Agent",
    "CompileFn",
    "Family",
    "Networks",
    "actor_critic_adam",
    "build_agent",
    "build_lagrangian",
]

# Every registered task has one cost signal; the losses and the controllers take m >= 1.
NUM_COSTS = 1

CompileFn = Callable[[Callable], Callable]
GradientStep = Callable[[TensorDictBase], TensorDictBase]


@dataclass
class Agent:
    """The learnable parts of a run and what updates them.

    ``policy`` collects (SAC, PPO: the stochastic actor; DDPG: the actor plus exploration
    noise); ``actor`` is evaluated deterministically. ``update(batch)`` takes one gradient step
    (the family's: critics, actor, temperature, targets) with ``optimizers`` and returns the
    detached losses and diagnostics, whose names are ``log_keys``. ``prepare(batch)``,
    on-policy only, computes what the gradient steps read from a whole collected batch (PPO: the
    advantages). ``lagrangian`` (None when unconstrained) updates lambda at the configured
    cadence and writes it into ``loss``; ``contrastive`` is S3RL's phase (None without it).
    """

    policy: TensorDictModuleBase
    actor: TensorDictModuleBase
    loss: LossModule
    update: GradientStep
    optimizers: dict[str, torch.optim.Optimizer]
    log_keys: tuple[str, ...]
    prepare: Callable[[TensorDictBase], TensorDictBase] | None = None
    lagrangian: LagrangianUpdater | None = None
    contrastive: ContrastivePhase | None = None


@dataclass
class Networks:
    """The run's network settings and the env's sizes: every family builds its actor and
    critics from them alike. ``settings`` has ``actor_hidden``, ``critic_hidden``,
    ``activation`` (a name of ``modules.ACTIVATIONS``), ``log_std_min`` and ``log_std_max``
    (trainer/config.py: ``NetworkConfig``)."""

    settings: Any
    observation_dim: int
    action_spec: TensorSpec

    @property
    def action_dim(self) -> int:
        return self.action_spec.shape[-1]

    @property
    def activation(self) -> type[nn.Module]:
        return ACTIVATIONS[self.settings.activation]

    def critics(self, builder: Callable, count: int) -> list:
        """``count`` critics, one module each, so each keeps its own orthogonal init (FSRL); a
        single module would be copied and re-initialised by torchrl."""
        hidden = tuple(self.settings.critic_hidden)
        return [
            builder(self.observation_dim, self.action_dim, hidden, activation_class=self.activation)
            for _ in range(count)
        ]

    def stochastic_actor(self) -> TensorDictModuleBase:
        """The paper's policy encoder + tanh-Gaussian head (SAC and PPO families)."""
        return build_s3rl_actor(
            self.observation_dim,
            self.action_spec,
            hidden=tuple(self.settings.actor_hidden),
            log_std_bounds=(self.settings.log_std_min, self.settings.log_std_max),
            activation=self.activation,
        )


@dataclass(frozen=True)
class Family:
    """An algorithm family: its typed config, when its gradient steps happen, and how its
    agent (actor, critics, loss, optimisers, gradient step) is built. ``seeds_in_one_process``:
    K seeds can share one batched gradient step (``seeds=[...]``; SAC: ``StackedSACLag``).
    A new family is a module that ends with one of these and its entries in
    ``registry.ALGORITHMS``."""

    name: str
    config: type[AlgoConfig]
    schedule: type[UpdateSchedule]
    build: Callable[[Any, Networks, CompileFn | None], Agent]
    seeds_in_one_process: bool = False


def actor_critic_adam(
    actor_params: TensorDictBase,
    critic_params: Sequence[TensorDictBase],
    actor_lr: float,
    critic_lr: float,
    **adam_kwargs,
) -> dict[str, torch.optim.Optimizer]:
    """``{"actor", "critic"}``: one Adam over the actor's trainable tensors and one over those of
    every critic (reward and cost together), as the DDPG and PPO families step them; buffers
    (e.g. the actor's action bounds) are skipped."""
    for name, lr in (("actor_lr", actor_lr), ("critic_lr", critic_lr)):
        if not lr > 0:
            raise ValueError(f"{name} must be > 0, got {lr!r}.")

    def trainable(params: TensorDictBase) -> list[torch.Tensor]:
        return [p for p in params.values(True, True) if p.requires_grad]

    critic = [p for params in critic_params for p in trainable(params)]
    return {
        "actor": torch.optim.Adam(trainable(actor_params), lr=actor_lr, **adam_kwargs),
        "critic": torch.optim.Adam(critic, lr=critic_lr, **adam_kwargs),
    }


def build_lagrangian(algo: AlgoConfig, cost_limit: float) -> LagrangianController | None:
    """The controller of ``algo.lagrangian`` (None: unconstrained)."""
    if algo.lagrangian == "pid":
        pid = algo.pid
        return PIDLagrangian(
            pid.kp,
            pid.ki,
            pid.kd,
            cost_limit=cost_limit,
            error_ema=pid.ema_alpha,
            cost_ema=pid.ema_alpha,
            derivative_delay=pid.derivative_delay,
            ki_inside_integral=pid.ki_inside_integral,
            derivative_history_init=pid.derivative_history_init,
            penalty_max=pid.penalty_max,
            lagrangian_init=algo.lagrangian_init,
        )
    if algo.lagrangian == "learned":
        return LearnedLagrangian(
            cost_limit,
            lr=algo.lagrangian_lr,
            lagrangian_init=algo.lagrangian_init,
            upper_bound=algo.lagrangian_max,
        )
    return None


def build_agent(
    family: Family,
    algo: AlgoConfig,
    nets: Networks,
    cost_limit: float,
    labelled: TensorDictReplayBuffer | None,
    compile_fn: CompileFn | None = None,
) -> Agent:
    """The family's agent (actor, critics, loss, optimisers, gradient step), then the
    Lagrangian and the contrastive phase, which every family takes alike. ``labelled`` is the
    buffer of labelled states the contrastive phase samples (off-policy: the replay buffer;
    on-policy: the FIFO of recent labelled states). ``compile_fn`` (e.g. ``torch.compile``)
    wraps the SAC family's loss calls."""
    agent = family.build(algo, nets, compile_fn)
    lagrangian = contrastive = None
    if algo.lagrangian != "none":
        lagrangian = LagrangianUpdater(
            # The controller's d: the share of the task's limit it aims at (1.0: the limit).
            build_lagrangian(algo, cost_limit * algo.lagrangian_target),
            agent.loss,
            cadence=algo.lagrangian_cadence,
            window=algo.lagrangian_window,
            warmup_frames=algo.lagrangian_warmup_frames,
            eval_window=algo.lagrangian_eval_window,
        )
    if algo.contrastive:
        if labelled is None:
            raise ValueError(
                "the contrastive phase needs the labelled buffer it samples from (off-policy: "
                "the replay buffer; on-policy: the FIFO of recent labelled states)"
            )
        contrastive = build_contrastive_phase(algo.contrastive_cfg, agent.actor, labelled)
    return dataclasses.replace(agent, lagrangian=lagrangian, contrastive=contrastive)
