"""Build a run's components from its config: envs, networks, losses, controller, buffer.

Each builder returns a plain TorchRL object, so a user can take one piece into their own loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor
from torchrl.objectives import SoftUpdate

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.envs import make_env
from s3rl_torchrl.modules import (
    ContrastivePhase,
    ReLU,
    build_cost_qvalue_network,
    build_qvalue_network,
    build_s3rl_actor,
    get_policy_encoder,
)
from s3rl_torchrl.objectives import (
    ForeachSoftUpdate,
    LagrangianController,
    LearnedLagrangian,
    PIDLagrangian,
    SACLagLoss,
    SACLagOptimizers,
    SafetyInfoNCELoss,
    make_sac_lag_optimizers,
)
from s3rl_torchrl.trainer.config import AlgoConfig, TrainConfig

# Every registered task has one cost signal; the loss and the controllers take m >= 1.
NUM_COSTS = 1

ACTIVATIONS: dict[str, type[nn.Module]] = {
    "relu": ReLU,  # nn.ReLU that stays fast under torch.compile (modules/activation.py)
    "tanh": nn.Tanh,
    "elu": nn.ELU,
    "silu": nn.SiLU,
}


def build_envs(cfg: TrainConfig) -> tuple[EnvBase, EnvBase]:
    """Training envs and separate test envs (seeded apart so they never share episodes)."""
    train_env = make_env(
        cfg.task.name,
        num_envs=cfg.collector.num_envs,
        seed=cfg.seed,
        device=cfg.device,
        batching=cfg.collector.batching,
    )
    test_env = make_env(
        cfg.task.name,
        num_envs=cfg.eval.num_envs,
        seed=cfg.seed + 100_000,
        device=cfg.device,
        batching=cfg.collector.batching,
    )
    return train_env, test_env


@dataclass
class Agent:
    """The learnable parts of a run and what updates them."""

    actor: ProbabilisticActor
    loss: SACLagLoss
    target_updater: SoftUpdate
    optimizers: SACLagOptimizers
    lagrangian: LagrangianController | None
    contrastive: ContrastivePhase | None


def build_lagrangian(algo: AlgoConfig, cost_limit: float) -> LagrangianController | None:
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
            penalty_max=pid.penalty_max,
            lagrangian_init=algo.lagrangian_init,
        )
    if algo.lagrangian == "learned":
        return LearnedLagrangian(
            cost_limit, lr=algo.lagrangian_lr, lagrangian_init=algo.lagrangian_init
        )
    return None


def build_agent(
    cfg: TrainConfig, env: EnvBase, replay_buffer: TensorDictReplayBuffer | None
) -> Agent:
    """Actor, critics, ``SACLagLoss``, optimisers, Lagrangian and contrastive phase."""
    algo, net = cfg.algo, cfg.network
    observation_dim = env.observation_spec["observation"].shape[-1]
    action_spec = env.action_spec_unbatched
    action_dim = action_spec.shape[-1]
    activation = ACTIVATIONS[net.activation]

    actor = build_s3rl_actor(
        observation_dim,
        action_spec,
        hidden=tuple(net.actor_hidden),
        log_std_bounds=(net.log_std_min, net.log_std_max),
        activation=activation,
    )

    # One module per critic (a list), so each keeps its own orthogonal init (FSRL); a single
    # module would be copied and re-initialised by torchrl.
    def critics(builder, count: int) -> list:
        return [
            builder(
                observation_dim, action_dim, tuple(net.critic_hidden), activation_class=activation
            )
            for _ in range(count)
        ]

    num_qvalue_nets = 2  # double critics (paper, FSRL)
    qvalue = critics(build_qvalue_network, num_qvalue_nets)
    constrained = algo.lagrangian != "none"
    # Unconstrained runs (sac, s3rl_nolag) have lambda fixed at 0: cost critics would only cost
    # time, so the loss is built without them (it is then exactly SACLoss).
    cost_qvalue = (
        critics(build_cost_qvalue_network, num_qvalue_nets * NUM_COSTS) if constrained else None
    )
    loss = SACLagLoss(
        actor,
        qvalue,
        cost_qvalue,
        num_costs=NUM_COSTS if constrained else 0,
        num_qvalue_nets=num_qvalue_nets,
        alpha_init=algo.alpha_init,
        fixed_alpha=not algo.auto_alpha,
        action_spec=action_spec,
        entropy_in_cost_target=algo.cost_entropy,
        rescaling=algo.rescaling,
        lagrangian_init=algo.lagrangian_init if constrained else 0.0,
    )
    loss.make_value_estimator(gamma=algo.gamma)
    target_updater = ForeachSoftUpdate(loss, tau=algo.tau)
    optimizers = make_sac_lag_optimizers(loss, algo.actor_lr, algo.critic_lr, algo.alpha_lr)
    lagrangian = build_lagrangian(algo, cfg.task.cost_limit) if constrained else None

    contrastive = None
    if algo.contrastive:
        if replay_buffer is None:
            raise ValueError("the contrastive phase needs the replay buffer it samples from")
        c = algo.contrastive_cfg
        infonce = SafetyInfoNCELoss(
            get_policy_encoder(actor),
            temperature=c.temperature,
            momentum_encoder=c.momentum_tau is not None,
        )
        view = SafeUnsafeSampler.contrastive_view(replay_buffer, c.batch_size)
        updater = None
        if c.momentum_tau is not None:
            updater = ForeachSoftUpdate(infonce, tau=c.momentum_tau)
        contrastive = ContrastivePhase(
            infonce, view, c.lr, num_steps=c.steps, target_updater=updater
        )
    return Agent(actor, loss, target_updater, optimizers, lagrangian, contrastive)


def build_replay_buffer(algo: AlgoConfig) -> TensorDictReplayBuffer:
    """One storage for everything; the sampler keeps the safe/unsafe partition as it writes."""
    return TensorDictReplayBuffer(
        storage=LazyTensorStorage(algo.buffer_size),
        sampler=SafeUnsafeSampler(),
        batch_size=algo.batch_size,
    )


def set_torch_threads(threads: int) -> None:
    if threads > 0:
        torch.set_num_threads(threads)
