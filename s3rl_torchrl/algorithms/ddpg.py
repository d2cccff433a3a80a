"""The DDPG family: FSRL's DDPG-Lag, DDPG, and DDPG-Lag with S3RL's contrastive phase
(``algo=ddpg_lag``, ``ddpg``, ``s3rl_ddpg_lag``).

- :class:`DDPGConfig`: the family's fields; FSRL's values (``fsrl/config/ddpgl_cfg.py``) are
  the defaults of :class:`~s3rl_torchrl.algorithms.config.OffPolicyConfig` plus the exploration
  noise;
- :func:`build_ddpg_agent`: the deterministic actor on the paper's policy encoder, Gaussian
  exploration noise for collecting, one critic of each kind (FSRL), ``DDPGLagLoss`` (torchrl's
  ``DDPGLoss`` when unconstrained), two Adam optimisers;
- :func:`ddpg_lag_update`: the gradient step in FSRL's order (``DDPGLagrangian.learn``):
  critics, then the actor on the updated critics, then the targets.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import DDPGLoss

from s3rl_torchrl.algorithms.agent import (
    NUM_COSTS,
    Agent,
    CompileFn,
    Family,
    Networks,
    actor_critic_adam,
)
from s3rl_torchrl.algorithms.config import OffPolicyConfig, check_range
from s3rl_torchrl.algorithms.schedule import OffPolicySchedule
from s3rl_torchrl.modules import (
    build_cost_qvalue_network,
    build_ddpg_exploration,
    build_deterministic_actor,
    build_qvalue_network,
)
from s3rl_torchrl.objectives import DDPGLagLoss, ForeachSoftUpdate

__all__ = ["DDPG", "DDPGConfig", "build_ddpg_agent", "ddpg_lag_update", "make_ddpg_lag_optimizers"]


@dataclass
class DDPGConfig(OffPolicyConfig):
    """DDPG with an optional Lagrangian and an optional contrastive phase (FSRL's DDPG-Lag)."""

    # Std of the Gaussian exploration noise in [-1, 1] action units (FSRL 0.1).
    exploration_noise: float = 0.1

    def check(self, path: str) -> None:
        super().check(path)
        check_range(f"{path}.exploration_noise", self.exploration_noise, 0.0)


def make_ddpg_lag_optimizers(
    loss: DDPGLoss, actor_lr: float = 5e-4, critic_lr: float = 1e-3, **adam_kwargs
) -> dict[str, torch.optim.Optimizer]:
    """FSRL's Adam optimisers, ``{"actor", "critic"}`` (reward and cost critics together;
    defaults: ``fsrl/config/ddpgl_cfg.py``). Works for ``DDPGLagLoss`` and torchrl's
    ``DDPGLoss``."""
    critics = [loss.value_network_params]
    if isinstance(loss, DDPGLagLoss):
        critics.append(loss.cost_value_network_params)
    return actor_critic_adam(loss.actor_network_params, critics, actor_lr, critic_lr, **adam_kwargs)


def ddpg_lag_update(
    loss: DDPGLoss,
    batch: TensorDictBase,
    optimizers: dict[str, torch.optim.Optimizer],
    target_updater=None,
) -> TensorDictBase:
    """One gradient step in FSRL's order (``DDPGLagrangian.learn``): critics, actor, targets.

    The actor loss sees the critics *after* their step. Returns the detached losses and the
    diagnostics ``reward_q``, ``cost_q``, ``lagrangian``. With torchrl's ``DDPGLoss`` (no cost
    critic, unconstrained DDPG) it is the same step without the cost entries.
    """
    constrained = isinstance(loss, DDPGLagLoss)
    if constrained:
        critic = loss.critic_loss(batch)
        critic_total = critic["loss_value"] + critic["loss_cost_value"]
    else:
        loss_value, _ = loss.loss_value(batch)
        critic = {"loss_value": loss_value}
        critic_total = loss_value
    optimizers["critic"].zero_grad(set_to_none=True)
    critic_total.backward()
    optimizers["critic"].step()

    loss_actor, metadata = loss.loss_actor(batch)
    optimizers["actor"].zero_grad(set_to_none=True)
    loss_actor.backward()
    optimizers["actor"].step()
    if target_updater is not None:
        target_updater.step()
    out = {
        "loss_actor": loss_actor.detach(),
        **{key: value.detach() for key, value in critic.items()},
        **metadata,
    }
    if constrained:
        out["lagrangian"] = loss.lagrangian.detach().clone()
    else:  # DDPGLoss's actor loss is -Q_r(s, mu(s)) and returns no diagnostics
        out["reward_q"] = -loss_actor.detach()
    return TensorDict(out, batch_size=[])


def build_ddpg_agent(algo: DDPGConfig, nets: Networks, compile_fn: CompileFn | None) -> Agent:
    """``DDPGLagLoss`` (torchrl's ``DDPGLoss`` when unconstrained) with one critic of each kind
    (FSRL), the deterministic actor plus Gaussian exploration noise. Always eager: ``compile``
    has no effect on this family."""
    actor = build_deterministic_actor(
        nets.observation_dim,
        nets.action_spec,
        hidden=tuple(nets.settings.actor_hidden),
        activation=nets.activation,
    )
    policy = build_ddpg_exploration(actor, nets.action_spec, sigma=algo.exploration_noise)
    (value,) = nets.critics(build_qvalue_network, 1)
    if algo.lagrangian != "none":
        (cost_value,) = nets.critics(build_cost_qvalue_network, 1)
        loss = DDPGLagLoss(
            actor,
            value,
            cost_value,
            num_costs=NUM_COSTS,
            rescaling=algo.rescaling,
            lagrangian_init=algo.lagrangian_init,
        )
        log_keys = ("loss_actor", "loss_value", "reward_q", "loss_cost_value", "cost_q")
    else:  # lambda fixed at 0: DDPGLagLoss would equal DDPGLoss with an unused cost critic
        loss = DDPGLoss(actor, value, delay_actor=True, delay_value=True, loss_function="l2")
        log_keys = ("loss_actor", "loss_value", "reward_q")
    loss.make_value_estimator(gamma=algo.gamma)
    target_updater = ForeachSoftUpdate(loss, tau=algo.tau)
    optimizers = make_ddpg_lag_optimizers(loss, algo.actor_lr, algo.critic_lr)

    def step(batch: TensorDictBase) -> TensorDictBase:
        return ddpg_lag_update(loss, batch, optimizers, target_updater)

    return Agent(
        policy=policy, actor=actor, loss=loss, update=step, optimizers=optimizers, log_keys=log_keys
    )


DDPG = Family(name="ddpg", config=DDPGConfig, schedule=OffPolicySchedule, build=build_ddpg_agent)
