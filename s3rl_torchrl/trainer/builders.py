"""Build a run's components from its config: envs, networks, losses, controller, buffer.

Each builder returns a plain TorchRL object, so a user can take one piece into their own loop.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import LazyTensorStorage, SamplerWithoutReplacement, TensorDictReplayBuffer
from torchrl.data.tensor_specs import TensorSpec
from torchrl.envs import EnvBase
from torchrl.objectives import ClipPPOLoss, DDPGLoss, LossModule, SoftUpdate

from s3rl_torchrl.data import GatherStorage, SafeUnsafeSampler
from s3rl_torchrl.envs import make_env
from s3rl_torchrl.modules import (
    ReLU,
    build_cost_qvalue_network,
    build_ddpg_exploration,
    build_deterministic_actor,
    build_qvalue_network,
    build_s3rl_actor,
    build_value_network,
    get_policy_encoder,
)
from s3rl_torchrl.modules.critics import COST_VALUE_KEY
from s3rl_torchrl.objectives import (
    DDPGLagLoss,
    DDPGLagOptimizers,
    ForeachSoftUpdate,
    GradedInfoNCELoss,
    LagrangianController,
    LagrangianUpdater,
    LearnedLagrangian,
    PIDLagrangian,
    PPOLagLoss,
    PPOLagOptimizers,
    SACLagLoss,
    SACLagOptimizers,
    SafetyInfoNCELoss,
    compute_ppo_advantages,
    ddpg_lag_update,
    make_ddpg_lag_optimizers,
    make_nstep_transform,
    make_ppo_lag_optimizers,
    make_sac_lag_optimizers,
    ppo_lag_update,
    sac_lag_update,
)
from s3rl_torchrl.trainer.contrastive import ContrastivePhase
from s3rl_torchrl.trainer.schedule import (
    OffPolicySchedule,
    OnPolicySchedule,
    ReplayUpdates,
    RolloutUpdates,
    UpdateSchedule,
    collector_batch_frames,
)
from s3rl_torchrl.transforms import COST_TO_GO_KEY, CostToGo

if TYPE_CHECKING:  # config.py imports FAMILIES from here
    from s3rl_torchrl.trainer.config import AlgoConfig, NetworkConfig, TrainConfig

# Every registered task has one cost signal; the loss and the controllers take m >= 1.
NUM_COSTS = 1

# The binary safety label (CostLabel): the probe and the binary contrastive phase read it.
SAFE_LABEL_KEY = ("next", "safe")
# Where each graded contrastive label is stored (algo.contrastive_cfg.label).
GRADED_LABEL_KEYS = {"cost_to_go": COST_TO_GO_KEY, "margin": ("next", "margin")}
# The bins (sampler strata) of a graded label when contrastive_cfg.label_bins is null, in the
# label's units. cost_to_go (gamma_c = 0.9, one cost per violating step): no cost in sight
# (< 0.05: the next cost is ~30 or more steps away), a cost ahead, in or next to a violation
# (>= 1), a sustained violation (>= 4). margin: violating (< 0), close to the limit, nearer
# than 1, farther (metres for the Goal tasks, the speed's units for the velocity tasks).
DEFAULT_LABEL_BINS = {"cost_to_go": (0.05, 1.0, 4.0), "margin": (0.0, 0.5, 1.0)}

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
        # The graded margin is a training-only label (contrasted or probed): only the training
        # env reads it, into ("next", "margin"), never into the observation.
        margin=probe_label(cfg.algo) == "margin",
    )
    test_env = make_env(
        cfg.task.name,
        num_envs=cfg.eval.num_envs,
        seed=cfg.seed + 100_000,
        device=cfg.device,
        batching=cfg.collector.batching,
    )
    return train_env, test_env


Update = Callable[[TensorDictBase], TensorDictBase]
CompileFn = Callable[[Callable], Callable]


@dataclass
class Agent:
    """The learnable parts of a run and what updates them.

    ``policy`` collects (SAC, PPO: the stochastic actor; DDPG: the actor plus exploration
    noise), ``actor`` is evaluated deterministically, ``update(batch)`` takes one gradient step
    (critics, actor, temperature, targets) and returns the detached losses and diagnostics,
    whose names are ``log_keys``. ``lagrangian`` (None when unconstrained) updates lambda at the
    configured cadence and writes it into ``loss``. ``prepare(batch)``, on-policy only, computes what the
    gradient steps read from a whole collected batch (PPO: the advantages); ``target_updater``
    is None without target networks (PPO).
    """

    policy: TensorDictModuleBase
    actor: TensorDictModuleBase
    loss: LossModule
    target_updater: SoftUpdate | None
    optimizers: SACLagOptimizers | DDPGLagOptimizers | PPOLagOptimizers
    lagrangian: LagrangianUpdater | None
    contrastive: ContrastivePhase | None
    update: Update
    log_keys: tuple[str, ...]
    prepare: Update | None = None


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


@dataclass
class Networks:
    """The run's network settings and the env's sizes: every family builds its actor and
    critics from them alike."""

    net: NetworkConfig
    observation_dim: int
    action_spec: TensorSpec

    @property
    def action_dim(self) -> int:
        return self.action_spec.shape[-1]

    @property
    def activation(self) -> type[nn.Module]:
        return ACTIVATIONS[self.net.activation]

    def critics(self, builder: Callable, count: int) -> list:
        """``count`` critics, one module each, so each keeps its own orthogonal init (FSRL); a
        single module would be copied and re-initialised by torchrl."""
        hidden = tuple(self.net.critic_hidden)
        return [
            builder(self.observation_dim, self.action_dim, hidden, activation_class=self.activation)
            for _ in range(count)
        ]

    def stochastic_actor(self) -> TensorDictModuleBase:
        """The paper's policy encoder + tanh-Gaussian head (SAC and PPO families)."""
        return build_s3rl_actor(
            self.observation_dim,
            self.action_spec,
            hidden=tuple(self.net.actor_hidden),
            log_std_bounds=(self.net.log_std_min, self.net.log_std_max),
            activation=self.activation,
        )


def build_sac_agent(algo: AlgoConfig, nets: Networks, compile_fn: CompileFn | None) -> Agent:
    """SAC family: ``SACLagLoss`` (exactly ``SACLoss`` when unconstrained), double critics."""
    constrained = algo.lagrangian != "none"
    actor = nets.stochastic_actor()
    num_qvalue_nets = 2  # double critics (paper, FSRL)
    qvalue = nets.critics(build_qvalue_network, num_qvalue_nets)
    # Unconstrained runs (sac, s3rl_nolag) have lambda fixed at 0: cost critics would only
    # cost time, so the loss is built without them (it is then exactly SACLoss).
    cost_qvalue = (
        nets.critics(build_cost_qvalue_network, num_qvalue_nets * NUM_COSTS)
        if constrained
        else None
    )
    loss = SACLagLoss(
        actor,
        qvalue,
        cost_qvalue,
        num_costs=NUM_COSTS if constrained else 0,
        num_qvalue_nets=num_qvalue_nets,
        alpha_init=algo.alpha_init,
        fixed_alpha=not algo.auto_alpha,
        action_spec=nets.action_spec,
        entropy_in_cost_target=algo.cost_entropy,
        rescaling=algo.rescaling,
        entropy_rescaling=algo.entropy_rescaling,
        cost_critic_read=algo.cost_critic_read,
        cost_nonnegative=algo.cost_nonnegative,
        cost_gamma=algo.cost_gamma,
        lagrangian_init=algo.lagrangian_init if constrained else 0.0,
    )
    loss.make_value_estimator(gamma=algo.gamma)
    target_updater = ForeachSoftUpdate(loss, tau=algo.tau)
    optimizers = make_sac_lag_optimizers(loss, algo.actor_lr, algo.critic_lr, algo.alpha_lr)
    update = _sac_update(
        loss, optimizers, target_updater, algo.update_order, compile_fn or (lambda fn: fn)
    )
    log_keys = tuple(k for k in loss.out_keys if k != "lagrangian")
    return Agent(actor, actor, loss, target_updater, optimizers, None, None, update, log_keys)


def build_ddpg_agent(algo: AlgoConfig, nets: Networks, compile_fn: CompileFn | None) -> Agent:
    """DDPG family: ``DDPGLagLoss`` (torchrl's ``DDPGLoss`` when unconstrained), one critic of
    each kind (FSRL), the deterministic actor plus Gaussian exploration noise."""
    actor = build_deterministic_actor(
        nets.observation_dim,
        nets.action_spec,
        hidden=tuple(nets.net.actor_hidden),
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

    def update(batch: TensorDictBase) -> TensorDictBase:
        return ddpg_lag_update(loss, batch, optimizers, target_updater)

    return Agent(policy, actor, loss, target_updater, optimizers, None, None, update, log_keys)


def build_ppo_agent(algo: AlgoConfig, nets: Networks, compile_fn: CompileFn | None) -> Agent:
    """PPO family: ``PPOLagLoss`` (torchrl's ``ClipPPOLoss`` when unconstrained) with the
    paper's stochastic actor (the policy encoder the contrastive phase trains) and one
    state-value network per signal (FSRL's PPO-Lag)."""
    actor = nets.stochastic_actor()
    hidden = tuple(nets.net.critic_hidden)
    value = build_value_network(nets.observation_dim, hidden, activation_class=nets.activation)
    # FSRL's PPO-Lag settings (config.AlgoConfig, docs/objectives.md): no entropy bonus,
    # squared-error critics weighted critic_coeff, advantages standardised per minibatch.
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

    def update(batch: TensorDictBase) -> TensorDictBase:
        return ppo_lag_update(loss, batch, optimizers, algo.max_grad_norm)

    def prepare(batch: TensorDictBase) -> TensorDictBase:
        return compute_ppo_advantages(loss, batch)

    return Agent(actor, actor, loss, None, optimizers, None, None, update, log_keys, prepare)


@dataclass(frozen=True)
class AlgoFamily:
    """An algorithm family: when its gradient steps happen (trainer/schedule.py) and how its
    agent (actor, critics, loss, optimisers, gradient step) is built. Adding a family is one
    entry here and one builder; adding an algorithm of a family is one entry of
    ``config.ALGO_FAMILIES`` and one YAML in ``configs/algo/``."""

    schedule: type[UpdateSchedule]
    build_agent: Callable[[AlgoConfig, Networks, CompileFn | None], Agent]


FAMILIES: dict[str, AlgoFamily] = {
    "sac": AlgoFamily(OffPolicySchedule, build_sac_agent),
    "ddpg": AlgoFamily(OffPolicySchedule, build_ddpg_agent),
    "ppo": AlgoFamily(OnPolicySchedule, build_ppo_agent),
}


def build_agent(
    cfg: TrainConfig,
    env: EnvBase,
    replay_buffer: TensorDictReplayBuffer | None,
    compile_fn: CompileFn | None = None,
) -> Agent:
    """Actor, critics, loss, optimisers, update (the family's builder, :data:`FAMILIES`), then
    the Lagrangian and the contrastive phase, which every family takes alike.

    ``compile_fn`` (e.g. ``torch.compile``) wraps the SAC family's loss calls.
    """
    algo = cfg.algo
    nets = Networks(cfg.network, env.observation_spec["observation"].shape[-1],
                    env.action_spec_unbatched)
    agent = FAMILIES[algo.family].build_agent(algo, nets, compile_fn)
    if algo.lagrangian != "none":
        agent.lagrangian = LagrangianUpdater(
            build_lagrangian(algo, cfg.task.cost_limit),
            agent.loss,
            cadence=algo.lagrangian_cadence,
            window=algo.lagrangian_window,
            warmup_frames=algo.lagrangian_warmup_frames,
        )
    if algo.contrastive:
        agent.contrastive = build_contrastive_phase(algo, agent.actor, replay_buffer)
    return agent


def build_contrastive_phase(
    algo: AlgoConfig, actor: TensorDictModuleBase, replay_buffer: TensorDictReplayBuffer | None
) -> ContrastivePhase:
    """S3RL's phase on the actor's policy encoder, sampling triplets from the labelled buffer."""
    if replay_buffer is None:
        raise ValueError(
            "the contrastive phase needs the labelled buffer it samples from (off-policy: "
            "the replay buffer; on-policy: the FIFO of recent labelled states)"
        )
    c = algo.contrastive_cfg
    if c.graded:
        infonce = GradedInfoNCELoss(
            get_policy_encoder(actor),
            temperature=c.temperature,
            positives=c.positives,
            momentum_encoder=c.momentum_tau is not None,
        )
        infonce.set_keys(label=GRADED_LABEL_KEYS[c.label])
    else:
        infonce = SafetyInfoNCELoss(
            get_policy_encoder(actor),
            temperature=c.temperature,
            momentum_encoder=c.momentum_tau is not None,
        )
    view = SafeUnsafeSampler.contrastive_view(replay_buffer, c.batch_size)
    updater = None
    if c.momentum_tau is not None:
        updater = ForeachSoftUpdate(infonce, tau=c.momentum_tau)
    return ContrastivePhase(infonce, view, c.lr, num_steps=c.steps, target_updater=updater)


def _sac_update(
    loss: SACLagLoss,
    optimizers: SACLagOptimizers,
    target_updater: SoftUpdate,
    update_order: str,
    compile_fn: CompileFn,
) -> Update:
    """The SAC family's gradient step in ``update_order`` (config.AlgoConfig)."""
    if update_order == "fsrl":
        critic_loss, actor_loss = compile_fn(loss.critic_loss), compile_fn(loss.actor_loss)

        def update(batch: TensorDictBase) -> TensorDictBase:
            return sac_lag_update(
                loss,
                batch,
                optimizers,
                target_updater,
                critic_loss=critic_loss,
                actor_loss=actor_loss,
            )

        return update

    loss_forward = compile_fn(loss)
    active = [o for o in optimizers if o is not None]

    def update(batch: TensorDictBase) -> TensorDictBase:
        # The paper's Algorithm 3: every loss from one forward, one backward, every optimiser.
        losses = loss_forward(batch)
        total = sum(v for k, v in losses.items() if k.startswith("loss_"))
        for optimizer in active:
            optimizer.zero_grad(set_to_none=True)
        total.backward()
        for optimizer in active:
            optimizer.step()
        target_updater.step()
        return losses.detach()

    return update


def graded_label(algo: AlgoConfig) -> str | None:
    """The graded contrastive label of a run (``cost_to_go`` or ``margin``), None if binary."""
    c = algo.contrastive_cfg
    return c.label if algo.contrastive and c.graded else None


def probe_label(algo: AlgoConfig) -> str:
    """The graded label the graded probe measures: the run's graded contrastive label, else
    ``cost_to_go`` (every task has a cost), so that binary and graded runs, and the baselines,
    are probed on the same label (the binary probe, too, runs for every algo)."""
    return graded_label(algo) or "cost_to_go"


def probe_label_key(algo: AlgoConfig) -> NestedKey:
    """Where the probed graded label is stored (:func:`probe_label`'s key)."""
    return GRADED_LABEL_KEYS[probe_label(algo)]


def probe_label_bins(algo: AlgoConfig) -> tuple[float, ...]:
    """The probe's bins: the graded sampler's strata (``contrastive_cfg.label_bins``, else the
    label's :data:`DEFAULT_LABEL_BINS`), so a binary run's probe balances the same bins as the
    graded run it is compared with."""
    edges = algo.contrastive_cfg.label_bins
    return DEFAULT_LABEL_BINS[probe_label(algo)] if edges is None else tuple(edges)


def build_labeller(algo: AlgoConfig) -> CostToGo | None:
    """What labels each collected batch before it is stored: :class:`CostToGo` when the run
    contrasts or probes the cost-to-go label (it needs the batch's time dimension), None
    otherwise (the binary label and the margin come with every step). Labelling does not
    change what is trained: it adds one entry to each stored step and draws no random
    numbers."""
    if probe_label(algo) == "cost_to_go":
        return CostToGo(algo.contrastive_cfg.label_gamma)
    return None


def build_sampler(algo: AlgoConfig) -> SafeUnsafeSampler:
    """The sampler partitions the buffer by the label the contrastive phase contrasts: safe /
    unsafe, or the bins of the graded label."""
    label = graded_label(algo)
    if label is None:
        return SafeUnsafeSampler(SAFE_LABEL_KEY)
    return SafeUnsafeSampler(GRADED_LABEL_KEYS[label], bin_edges=probe_label_bins(algo))


def build_replay_buffer(algo: AlgoConfig) -> TensorDictReplayBuffer:
    """One storage for everything; the sampler keeps the label partition as it writes.

    Off-policy: the replay buffer the gradient steps sample. On-policy: the FIFO of the last
    ``buffer_size`` labelled states, for the contrastive phase and the probe only.
    ``GatherStorage``: torchrl's storage with a faster gather of each sampled batch.
    """
    return TensorDictReplayBuffer(
        storage=GatherStorage(algo.buffer_size),
        sampler=build_sampler(algo),
        batch_size=algo.batch_size,
    )


def build_rollout_buffer(cfg: TrainConfig) -> TensorDictReplayBuffer:
    """The on-policy batch: one collect's transitions, each PPO epoch a new permutation of
    ``ceil(frames / batch_size)`` minibatches (the last one shorter)."""
    return TensorDictReplayBuffer(
        storage=LazyTensorStorage(collector_batch_frames(cfg.collector)),
        sampler=SamplerWithoutReplacement(drop_last=False),
        batch_size=cfg.algo.batch_size,
    )


def _labelled_keys(
    algo: AlgoConfig, agent: Agent, replay_buffer: TensorDictReplayBuffer
) -> list:
    """The sampler's label, the binary and graded probes' labels, and the policy encoder's
    inputs (the contrastive phase and the probes embed them)."""
    keys = [
        replay_buffer.sampler.label_key,
        SAFE_LABEL_KEY,
        probe_label_key(algo),
        *get_policy_encoder(agent.actor).in_keys,
    ]
    phase = agent.contrastive
    if phase is not None:
        role = phase.loss.tensor_keys.contrastive_role  # written by the sampler per batch
        keys += [key for key in phase.loss.in_keys if key != role]
    return list(dict.fromkeys(keys))


def build_updates(
    cfg: TrainConfig, agent: Agent, replay_buffer: TensorDictReplayBuffer
) -> ReplayUpdates | RolloutUpdates:
    """The run-time side of the family's update schedule (trainer/schedule.py).

    The buffers keep what is read back from them, nothing else: a sample gathers every stored
    entry, and the collector and transforms write ~27 (episode sums, counters, the policy's
    outputs, ...), which made drawing a batch cost 0.86 ms instead of 0.58.
    """
    algo, loss = cfg.algo, agent.loss
    schedule = algo.schedule(cfg.collector)
    labelled = _labelled_keys(algo, agent, replay_buffer)
    if isinstance(schedule, OnPolicySchedule):
        keys = list(loss.in_keys)
        advantage_keys = ("advantage", "value_target", "cost_advantage", "cost_value_target")
        keys += [
            getattr(loss.tensor_keys, k) for k in advantage_keys if hasattr(loss.tensor_keys, k)
        ]
        return RolloutUpdates(
            schedule,
            build_rollout_buffer(cfg),
            agent.prepare,
            list(dict.fromkeys(keys)),
            replay_buffer,
            labelled,
        )
    # Off-policy (OffPolicySchedule). n-step windows need consecutive batches of the same env
    # copies: the transform keeps the last n frames of each copy until the next batch (paper:
    # n = 2).
    # Labels describe their own step: n-step keeps them at t (a graded one as the binary one).
    keep = ["safe", probe_label_key(algo)[-1]]
    nstep = (
        make_nstep_transform(
            algo.n_step, algo.gamma, keep_keys=tuple(keep), cost_gamma=algo.cost_gamma
        )
        if algo.n_step > 1
        else None
    )
    # The losses' inputs (n-step reward and discount exponent included) and the labelled keys.
    keys = [*loss.in_keys, loss.value_estimator.tensor_keys.steps_to_next_obs, *labelled]
    return ReplayUpdates(schedule, replay_buffer, list(dict.fromkeys(keys)), nstep)


def set_torch_threads(threads: int) -> None:
    if threads > 0:
        torch.set_num_threads(threads)
