"""The PPO family: FSRL's PPO-Lag, PPO, and PPO-Lag with S3RL's contrastive phase
(``algo=ppo_lag``, ``ppo``, ``s3rl_ppo_lag``), on-policy.

- :class:`PPOConfig`: the family's fields, FSRL's PPO-Lag values (``fsrl/config/ppol_cfg.py``)
  by default, so that its YAMLs name only the algorithm;
- :func:`build_ppo_agent`: the paper's stochastic actor (the policy encoder the contrastive
  phase trains), one state-value network per signal, ``PPOLagLoss`` (torchrl's ``ClipPPOLoss``
  when unconstrained), Adam over actor and critics;
- :func:`compute_ppo_advantages`: GAE on each collected batch, before its epochs;
- :func:`ppo_lag_update`: one minibatch step (the summed losses, one backward, the global
  gradient-norm clip, both optimisers).

Its schedule is on-policy (``algorithms/schedule.py``: ``ppo_epochs`` passes of minibatches
over each collect).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from torchrl.objectives import ClipPPOLoss

from s3rl_torchrl.algorithms.agent import Agent, CompileFn, Family, Networks, actor_critic_adam
from s3rl_torchrl.algorithms.config import (
    AlgoConfig,
    check_choice,
    check_positive,
    check_range,
)
from s3rl_torchrl.algorithms.schedule import OnPolicySchedule
from s3rl_torchrl.modules import build_value_network
from s3rl_torchrl.modules.critics import COST_VALUE_KEY
from s3rl_torchrl.objectives import PPOLagLoss
from s3rl_torchrl.objectives.ppo_lag import COST_SURROGATES

__all__ = [
    "PPO",
    "PPOConfig",
    "build_ppo_agent",
    "compute_ppo_advantages",
    "make_ppo_lag_optimizers",
    "ppo_lag_update",
]


@dataclass
class PPOConfig(AlgoConfig):
    """PPO with an optional Lagrangian and an optional contrastive phase; the defaults are
    FSRL's PPO-Lag (``batch_size`` is the minibatch size, ``buffer_size`` the FIFO of labelled
    states the contrastive phase and the probes sample)."""

    actor_lr: float = 5e-4
    critic_lr: float = 5e-4  # FSRL: one Adam with lr 5e-4 over actor and critics
    ppo_epochs: int = 4  # passes over each collected batch (FSRL repeat_per_collect)
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2  # FSRL eps_clip
    critic_coeff: float = 0.25  # FSRL vf_coef, both critics
    max_grad_norm: float | None = 0.5  # clip of the gradient norm of all parameters
    # PPO-Lag's cost term: "unclipped" (FSRL) or "clipped" (OmniSafe), objectives/ppo_lag.py
    cost_surrogate: str = "unclipped"

    def check(self, path: str) -> None:
        super().check(path)
        check_range(f"{path}.ppo_epochs", self.ppo_epochs, 1)
        check_range(f"{path}.gae_lambda", self.gae_lambda, 0.0, 1.0)
        check_positive(f"{path}.clip_epsilon", self.clip_epsilon)
        check_positive(f"{path}.critic_coeff", self.critic_coeff)
        if self.max_grad_norm is not None:
            check_positive(f"{path}.max_grad_norm", self.max_grad_norm)
        check_choice(f"{path}.cost_surrogate", self.cost_surrogate, COST_SURROGATES)


def make_ppo_lag_optimizers(
    loss: ClipPPOLoss, actor_lr: float = 5e-4, critic_lr: float = 5e-4, **adam_kwargs
) -> dict[str, torch.optim.Optimizer]:
    """Adam over the actor and Adam over the critics (reward and cost together),
    ``{"actor", "critic"}``. FSRL has one Adam over both (``lr = 5e-4``); Adam is
    per-parameter, so two with the same learning rate take the same steps. Works for
    ``PPOLagLoss`` and torchrl's ``ClipPPOLoss``."""
    critics = [loss.critic_network_params]
    if isinstance(loss, PPOLagLoss):
        critics.append(loss.cost_critic_network_params)
    return actor_critic_adam(loss.actor_network_params, critics, actor_lr, critic_lr, **adam_kwargs)


@torch.no_grad()
def compute_ppo_advantages(loss: ClipPPOLoss, batch: TensorDictBase) -> TensorDictBase:
    """GAE on a collected batch ``[*B, T]`` (time last), in place, before the PPO epochs: the
    reward and cost advantages for ``PPOLagLoss`` (:meth:`PPOLagLoss.compute_advantages`),
    the reward ones for torchrl's ``ClipPPOLoss`` (as its forward computes them)."""
    if isinstance(loss, PPOLagLoss):
        return loss.compute_advantages(batch)
    loss.value_estimator(
        batch,
        params=loss.critic_network_params.detach(),
        target_params=loss.target_critic_network_params,
    )
    return batch


def ppo_lag_update(
    loss: ClipPPOLoss,
    batch: TensorDictBase,
    optimizers: dict[str, torch.optim.Optimizer],
    max_grad_norm: float | None = None,
) -> TensorDictBase:
    """One PPO minibatch step: the sum of the ``loss_*`` entries (policy, reward critic, and
    the cost critic for ``PPOLagLoss``), one backward, the gradient norm of all parameters
    clipped to ``max_grad_norm`` (FSRL/tianshou clip actor and critics together), then both
    optimisers. Returns the detached losses and diagnostics."""
    losses = loss(batch)
    total = sum(value for key, value in losses.items() if key.startswith("loss_"))
    for optimizer in optimizers.values():
        optimizer.zero_grad(set_to_none=True)
    total.backward()
    if max_grad_norm is not None:
        params = [
            p for opt in optimizers.values() for group in opt.param_groups for p in group["params"]
        ]
        torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
    for optimizer in optimizers.values():
        optimizer.step()
    return losses.detach()


def build_ppo_agent(algo: PPOConfig, nets: Networks, compile_fn: CompileFn | None) -> Agent:
    """``PPOLagLoss`` (torchrl's ``ClipPPOLoss`` when unconstrained) with the paper's stochastic
    actor and one state-value network per signal (FSRL's PPO-Lag). Always eager: ``compile``
    has no effect on this family."""
    actor = nets.stochastic_actor()
    hidden = tuple(nets.settings.critic_hidden)
    value = build_value_network(nets.observation_dim, hidden, activation_class=nets.activation)
    # FSRL's PPO-Lag settings: no entropy bonus, squared-error critics weighted critic_coeff,
    # advantages standardised per minibatch.
    ppo_kwargs = dict(
        clip_epsilon=algo.clip_epsilon,
        entropy_bonus=False,
        critic_coeff=algo.critic_coeff,
        loss_critic_type="l2",
        normalize_advantage=True,
    )
    log_keys = ("loss_objective", "loss_critic", "kl_approx", "clip_fraction")
    if algo.lagrangian != "none":
        cost_value = build_value_network(
            nets.observation_dim, hidden, out_key=COST_VALUE_KEY, activation_class=nets.activation
        )
        loss = PPOLagLoss(
            actor,
            value,
            cost_value,
            cost_surrogate=algo.cost_surrogate,
            rescaling=algo.rescaling,
            lagrangian_init=algo.lagrangian_init,
            **ppo_kwargs,
        )
        log_keys += ("loss_cost_critic",)
    else:  # lambda fixed at 0: PPOLagLoss would equal ClipPPOLoss with an unused cost critic
        loss = ClipPPOLoss(actor, value, **ppo_kwargs)
    loss.make_value_estimator(gamma=algo.gamma, lmbda=algo.gae_lambda)
    optimizers = make_ppo_lag_optimizers(loss, algo.actor_lr, algo.critic_lr)

    def step(batch: TensorDictBase) -> TensorDictBase:
        return ppo_lag_update(loss, batch, optimizers, algo.max_grad_norm)

    def prepare(batch: TensorDictBase) -> TensorDictBase:
        return compute_ppo_advantages(loss, batch)

    return Agent(
        policy=actor,
        actor=actor,
        loss=loss,
        update=step,
        optimizers=optimizers,
        log_keys=log_keys,
        prepare=prepare,
    )


PPO = Family(name="ppo", config=PPOConfig, schedule=OnPolicySchedule, build=build_ppo_agent)
