"""Typed configuration of a training run: one dataclass per component, stored in Hydra's
ConfigStore so that every YAML under ``configs/`` is type-checked against it.

Types are checked by OmegaConf when Hydra merges the YAMLs and overrides; values (ranges and
choices) are checked by :func:`validate`, which every entry point calls before it builds
anything, so a bad override fails with the field's name and what it accepts.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from s3rl_torchrl.envs import BATCHING_CHOICES, get_task, require_task_module, task_names
from s3rl_torchrl.objectives.graded_infonce import GRADED_POSITIVES
from s3rl_torchrl.objectives.lagrangian import LAGRANGIAN_CADENCES
from s3rl_torchrl.objectives.sac_lag import COST_CRITIC_READS
from s3rl_torchrl.trainer.builders import FAMILIES
from s3rl_torchrl.trainer.schedule import UpdateSchedule, collector_batch_frames

# The algorithm registry: `algo=<name>` (configs/algo/<name>.yaml) -> its family, whose entry in
# builders.FAMILIES builds the actor, the loss and the gradient step and says when gradient
# steps happen (trainer/schedule.py). Adding an algorithm of an existing family is one entry
# here and one YAML.
ALGO_FAMILIES = {
    "s3rl": "sac",
    "sac_lag": "sac",
    "sac": "sac",
    "s3rl_nolag": "sac",
    "ddpg_lag": "ddpg",
    "ddpg": "ddpg",
    "s3rl_ddpg_lag": "ddpg",
    "ppo_lag": "ppo",
    "ppo": "ppo",
    "s3rl_ppo_lag": "ppo",
}
ALGO_NAMES = tuple(ALGO_FAMILIES)
# The algorithms without a Lagrange multiplier (their YAML sets `lagrangian: none`): a preset
# that picks the controller (experiment=safe) leaves them unconstrained (`s3rl_lagrangian`).
UNCONSTRAINED_ALGOS = ("sac", "s3rl_nolag", "ddpg", "ppo")
COST_SURROGATES = ("unclipped", "clipped")
LAGRANGIAN_CHOICES = ("pid", "learned", "none")
UPDATE_ORDERS = ("joint", "fsrl")
ACTIVATIONS = ("relu", "tanh", "elu", "silu")
LOGGER_BACKENDS = ("csv", "tensorboard", "wandb", "mlflow", "none")
# backend -> (module it imports, the package extra that installs it)
LOGGER_PACKAGES = {
    "tensorboard": ("tensorboard", "tensorboard"),
    "wandb": ("wandb", "wandb"),
    "mlflow": ("mlflow", "mlflow"),
}
DEVICES = ("cpu", "cuda", "mps")
# The contrastive phase's safety label (docs/representation.md): the paper's binary safe/unsafe
# label, the discounted cost-to-go (transforms.CostToGo) or the task's margin (TaskSpec).
CONTRASTIVE_LABELS = ("binary", "cost_to_go", "margin")


class ConfigError(ValueError):
    """A configuration value is out of range or not one of its choices."""


def _fail(path: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"Invalid value {value!r} for '{path}': {allowed}.")


def _check_cpp_compiler(path: str) -> None:
    """torch.compile on CPU builds C++ kernels: fail here, not at the first gradient step."""
    from torch._inductor import config as inductor_config
    from torch._inductor.cpp_builder import get_cpp_compiler
    from torch._inductor.exc import InvalidCxxCompiler

    try:
        get_cpp_compiler()
    except InvalidCxxCompiler:
        tried = [cxx for cxx in inductor_config.cpp.cxx if cxx]
        _fail(
            path,
            True,
            f"torch.compile on CPU needs a C++ compiler and none of {tried} runs (or set CXX); "
            "install one (Debian/Ubuntu: apt-get install g++) or pass compile=false",
        )


def _check_finite(obj: Any, path: str) -> None:
    """Every float field of a config (nested dataclasses included) is a finite number: NaN
    passes every range check (its comparisons are all false) and would fail deep inside."""
    for f in fields(obj):
        value, name = getattr(obj, f.name), f"{path}.{f.name}" if path else f.name
        if is_dataclass(value):
            _check_finite(value, name)
        elif isinstance(value, float) and not math.isfinite(value):
            _fail(name, value, "must be a finite number")


def _check_choice(path: str, value: Any, choices: tuple) -> None:
    if value not in choices:
        _fail(path, value, "allowed values are " + ", ".join(map(str, choices)))


def _check_range(
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
        _fail(path, value, f"must be in {lo}, {hi}")


@dataclass
class TaskConfig:
    """Which task, and its per-episode cost limit d.

    Each ``task=<id>`` option of the ConfigStore carries the registry's default ``cost_limit``
    for that task (the paper's 10 for every task, Table 3); ``task.cost_limit=...`` overrides it.
    """

    name: str = MISSING
    cost_limit: float = 10.0

    def check(self, path: str) -> None:
        _check_choice(f"{path}.name", self.name, tuple(task_names()))
        _check_range(f"{path}.cost_limit", self.cost_limit, 0.0)
        try:  # an optional package the task needs (the Bullet tasks): fail before building
            require_task_module(get_task(self.name))
        except ImportError as err:
            _fail(f"{path}.name", self.name, str(err))


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
        _check_choice(
            f"{path}.derivative_history_init", self.derivative_history_init, ("limit", "zero")
        )
        for name in ("kp", "ki", "kd"):
            _check_range(f"{path}.{name}", getattr(self, name), 0.0)
        _check_range(f"{path}.ema_alpha", self.ema_alpha, 0.0, 1.0)
        _check_range(f"{path}.derivative_delay", self.derivative_delay, 1)
        if self.penalty_max is not None:
            _check_range(f"{path}.penalty_max", self.penalty_max, 0.0, low_inclusive=False)


@dataclass
class ContrastiveConfig:
    """The S3RL representation phase (paper §3.4, Table 3)."""

    temperature: float = 0.7
    batch_size: int = 64  # B: B anchors, B positives, B negatives per InfoNCE step
    update_interval: int = 1000  # T: gradient steps between phases (enc_update_steps)
    steps: int = 50  # E: InfoNCE steps per phase (enc_training_epoch)
    lr: float = 5e-4
    momentum_tau: float | None = None  # MoCo-style target encoder when set
    # The safety label the phase contrasts: "binary" (the paper's, SafetyInfoNCELoss),
    # "cost_to_go" or "margin" (graded: GradedInfoNCELoss, triplets drawn by label bin).
    label: str = "binary"
    label_gamma: float = 0.9  # cost_to_go's gamma_c (horizon ~ 1 / (1 - gamma_c) steps)
    # Inner edges of the graded label's bins (the sampler's strata); None: the label's default
    # (builders.DEFAULT_LABEL_BINS), in the label's units.
    label_bins: list[float] | None = None
    positives: str = "paired"  # graded loss: "paired" (Algorithm 4's pairs) or "all" (RnC)

    @property
    def graded(self) -> bool:
        return self.label != "binary"

    def check(self, path: str) -> None:
        _check_range(f"{path}.temperature", self.temperature, 0.0, low_inclusive=False)
        _check_range(f"{path}.batch_size", self.batch_size, 1)
        _check_range(f"{path}.update_interval", self.update_interval, 1)
        _check_range(f"{path}.steps", self.steps, 1)
        _check_range(f"{path}.lr", self.lr, 0.0, low_inclusive=False)
        if self.momentum_tau is not None:
            _check_range(f"{path}.momentum_tau", self.momentum_tau, 0.0, 1.0, low_inclusive=False)
        _check_choice(f"{path}.label", self.label, CONTRASTIVE_LABELS)
        _check_choice(f"{path}.positives", self.positives, GRADED_POSITIVES)
        if not 0.0 <= self.label_gamma < 1.0:
            _fail(f"{path}.label_gamma", self.label_gamma, "must be in [0.0, 1.0)")
        if self.label_bins is not None:
            edges = list(self.label_bins)
            increasing = all(a < b for a, b in zip(edges, edges[1:]))
            if not edges or not increasing or len(edges) > 126:
                _fail(
                    f"{path}.label_bins",
                    edges,
                    "must be null or 1 to 126 strictly increasing bin edges",
                )


@dataclass
class AlgoConfig:
    """SAC, DDPG or PPO with an optional Lagrangian and an optional contrastive phase.

    Defaults: the paper's (SAC family); configs/algo/ddpg*.yaml set FSRL's DDPG-Lag values and
    configs/algo/*ppo*.yaml FSRL's PPO-Lag values (fsrl/config/ppol_cfg.py).
    """

    name: str = "s3rl"
    lagrangian: str = "pid"
    contrastive: bool = True
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
    rescaling: bool = True
    cost_entropy: bool = True  # subtract alpha*log_pi in the cost targets (FSRL, paper)
    # SAC family, the cost critics under the Lagrangian (objectives/sac_lag.py, docs/objectives.md
    # "Sound critics"); the defaults are FSRL's (experiment=paper), configs/critic/ names sets.
    # How the pair is read in the cost targets and the actor loss: min (FSRL), max or mean.
    cost_critic_read: str = "min"
    cost_nonnegative: bool = False  # clamp the cost value at 0 in its target and actor read
    # The cost critics' own discount (and the n-step cost sums'); None: gamma (FSRL).
    cost_gamma: float | None = None
    # With rescaling: divide the entropy term by 1 + lambda too (FSRL); false keeps alpha's
    # term out of the rescaling, so auto alpha does not grow with lambda.
    entropy_rescaling: bool = True
    gamma: float = 0.99
    tau: float = 0.05
    n_step: int = 2
    actor_lr: float = 5e-4
    critic_lr: float = 1e-3
    alpha_lr: float = 3e-4
    alpha_init: float = 0.005
    auto_alpha: bool = True
    batch_size: int = 256
    update_per_step: float = 0.2
    # "joint": one forward, one backward of the summed losses (the paper's Algorithm 3; faster).
    # "fsrl": critics step first, then the actor loss on the updated critics, then alpha.
    update_order: str = "joint"
    # DDPG family: std of the Gaussian exploration noise in [-1, 1] action units (FSRL 0.1).
    exploration_noise: float = 0.1
    # Off-policy: the replay buffer. PPO family: the FIFO of recent labelled states that the
    # contrastive phase and the linear probe sample (docs/representation.md).
    buffer_size: int = 100_000
    # PPO family (FSRL's PPO-Lag, fsrl/config/ppol_cfg.py); batch_size is the minibatch size.
    ppo_epochs: int = 4  # passes over each collected batch (FSRL repeat_per_collect)
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2  # FSRL eps_clip
    critic_coeff: float = 0.25  # FSRL vf_coef, both critics
    max_grad_norm: float | None = 0.5  # clip of the gradient norm of all parameters
    # PPO-Lag's cost term: "unclipped" (FSRL) or "clipped" (OmniSafe), objectives/ppo_lag.py
    cost_surrogate: str = "unclipped"
    contrastive_cfg: ContrastiveConfig = field(default_factory=ContrastiveConfig)

    @property
    def family(self) -> str:
        """``"sac"``, ``"ddpg"`` or ``"ppo"`` (:data:`ALGO_FAMILIES`)."""
        return ALGO_FAMILIES.get(self.name, "")

    def schedule(self, collector: CollectorConfig) -> UpdateSchedule:
        """The family's update schedule for these collector settings (``builders.FAMILIES``)."""
        return FAMILIES[self.family].schedule(collector, self)

    def check(self, path: str) -> None:
        _check_choice(f"{path}.name", self.name, ALGO_NAMES)
        if self.family == "ddpg" and self.update_order != "fsrl":
            # DDPG(-Lag) steps in FSRL's order only (ddpg_lag_update): critics, then the actor.
            _fail(f"{path}.update_order", self.update_order, "DDPG algorithms need fsrl")
        _check_choice(f"{path}.lagrangian", self.lagrangian, LAGRANGIAN_CHOICES)
        _check_choice(f"{path}.update_order", self.update_order, UPDATE_ORDERS)
        self.pid.check(f"{path}.pid")
        self.contrastive_cfg.check(f"{path}.contrastive_cfg")
        _check_range(f"{path}.lagrangian_lr", self.lagrangian_lr, 0.0, low_inclusive=False)
        _check_range(f"{path}.lagrangian_init", self.lagrangian_init, 0.0)
        _check_choice(f"{path}.lagrangian_cadence", self.lagrangian_cadence, LAGRANGIAN_CADENCES)
        _check_range(f"{path}.lagrangian_window", self.lagrangian_window, 1)
        _check_range(f"{path}.lagrangian_warmup_frames", self.lagrangian_warmup_frames, 0)
        if self.lagrangian_max is not None:
            _check_range(f"{path}.lagrangian_max", self.lagrangian_max, 0.0, low_inclusive=False)
            if self.lagrangian != "learned":
                _fail(
                    f"{path}.lagrangian_max",
                    self.lagrangian_max,
                    f"bounds the learned multiplier only (algo.lagrangian={self.lagrangian!r}); "
                    "the PID's bound is algo.pid.penalty_max",
                )
        _check_choice(f"{path}.cost_critic_read", self.cost_critic_read, COST_CRITIC_READS)
        if self.cost_gamma is not None:
            _check_range(f"{path}.cost_gamma", self.cost_gamma, 0.0, 1.0)
        _check_range(f"{path}.gamma", self.gamma, 0.0, 1.0)
        _check_range(f"{path}.tau", self.tau, 0.0, 1.0, low_inclusive=False)
        _check_range(f"{path}.n_step", self.n_step, 1)
        for name in ("actor_lr", "critic_lr", "alpha_lr", "alpha_init"):
            _check_range(f"{path}.{name}", getattr(self, name), 0.0, low_inclusive=False)
        _check_range(f"{path}.batch_size", self.batch_size, 1)
        _check_range(f"{path}.update_per_step", self.update_per_step, 0.0, low_inclusive=False)
        _check_range(f"{path}.exploration_noise", self.exploration_noise, 0.0)
        _check_range(f"{path}.buffer_size", self.buffer_size, self.batch_size)
        _check_range(f"{path}.ppo_epochs", self.ppo_epochs, 1)
        _check_range(f"{path}.gae_lambda", self.gae_lambda, 0.0, 1.0)
        _check_range(f"{path}.clip_epsilon", self.clip_epsilon, 0.0, low_inclusive=False)
        _check_range(f"{path}.critic_coeff", self.critic_coeff, 0.0, low_inclusive=False)
        if self.max_grad_norm is not None:
            _check_range(f"{path}.max_grad_norm", self.max_grad_norm, 0.0, low_inclusive=False)
        _check_choice(f"{path}.cost_surrogate", self.cost_surrogate, COST_SURROGATES)


@dataclass
class NetworkConfig:
    """Actor trunk (the policy encoder) and critic MLPs; they share no parameters."""

    actor_hidden: list[int] = field(default_factory=lambda: [128, 128])
    critic_hidden: list[int] = field(default_factory=lambda: [128, 128])
    activation: str = "relu"
    log_std_min: float = -20.0
    log_std_max: float = 2.0

    def check(self, path: str) -> None:
        for name in ("actor_hidden", "critic_hidden"):
            sizes = getattr(self, name)
            if len(sizes) == 0 or any(int(s) < 1 for s in sizes):
                _fail(f"{path}.{name}", list(sizes), "must be a non-empty list of sizes >= 1")
        _check_choice(f"{path}.activation", self.activation, ACTIVATIONS)
        if not self.log_std_min < self.log_std_max:
            _fail(f"{path}.log_std_min", self.log_std_min, "must be below log_std_max")


@dataclass
class CollectorConfig:
    """How frames are gathered: torchrl ``Collector`` over ``make_env``."""

    num_envs: int = 10
    batching: str = "sync_vector"
    frames_per_batch: int = 10_000
    total_frames: int = 1_000_000
    init_random_frames: int = 10_000
    frames_per_epoch: int = 10_000  # evaluation and checkpoint cadence

    def check(self, path: str) -> None:
        _check_range(f"{path}.num_envs", self.num_envs, 1)
        _check_choice(f"{path}.batching", self.batching, BATCHING_CHOICES)
        _check_range(f"{path}.frames_per_batch", self.frames_per_batch, self.num_envs)
        _check_range(f"{path}.total_frames", self.total_frames, 1)
        _check_range(f"{path}.init_random_frames", self.init_random_frames, 0)
        _check_range(f"{path}.frames_per_epoch", self.frames_per_epoch, 1)


@dataclass
class EvalConfig:
    """Deterministic evaluation on separate test envs."""

    num_envs: int = 2
    episodes: int = 2  # per epoch
    final_episodes: int = 10
    # Steps per evaluation rollout; None: the task's episode length (registry), so that each
    # rollout of each test env holds one whole episode.
    max_steps: int | None = None
    random_baseline: bool = True  # add a random-policy row to the final table

    def check(self, path: str) -> None:
        _check_range(f"{path}.num_envs", self.num_envs, 1)
        _check_range(f"{path}.episodes", self.episodes, 1)
        _check_range(f"{path}.final_episodes", self.final_episodes, 1)
        if self.max_steps is not None:
            _check_range(f"{path}.max_steps", self.max_steps, 1)


@dataclass
class LoggerConfig:
    """torchrl logger backend; CSV needs no server, W&B runs offline by default."""

    backend: str = "csv"
    project: str = "s3rl-torchrl"
    wandb_mode: str = "offline"
    progress_bar: bool = True

    def check(self, path: str) -> None:
        _check_choice(f"{path}.backend", self.backend, LOGGER_BACKENDS)
        _check_choice(f"{path}.wandb_mode", self.wandb_mode, ("offline", "online", "disabled"))
        module, extra = LOGGER_PACKAGES.get(self.backend, (None, None))
        if module is not None and importlib.util.find_spec(module) is None:
            _fail(
                f"{path}.backend",
                self.backend,
                f"needs the '{module}' package: pip install -e \".[{extra}]\" "
                f"(or choose csv or none)",
            )


def _check_learns(collector: CollectorConfig, algo: AlgoConfig, prefix: str) -> None:
    """Refuse a run that would evaluate an untrained policy as if it were trained."""
    schedule = algo.schedule(collector)
    if schedule.planned_gradient_steps(stop_at=1) > 0:
        return
    batch = collector_batch_frames(collector)

    def learns(**changes: int) -> bool:
        changed = CollectorConfig(**{**vars(collector), **changes})
        return algo.schedule(changed).planned_gradient_steps(stop_at=1) > 0

    options = []
    # The fewest whole batches that learn with the other values unchanged. Bounded: once past
    # init_random_frames and batch_size stored transitions (n-step holds back n_step frames
    # per env), every batch owes update_per_step * batch steps.
    start = max(collector.init_random_frames, algo.batch_size + algo.n_step * collector.num_envs)
    limit = start + batch * (1 + math.ceil(1.0 / (algo.update_per_step * batch)))
    total = next(
        (n for n in range(batch, limit + batch, batch) if learns(total_frames=n)), None
    )
    if total is not None:
        options.append(f"raise {prefix}collector.total_frames to {total} or more")
    last_batch_end = math.ceil(collector.total_frames / batch) * batch
    if learns(init_random_frames=last_batch_end):
        options.append(
            f"lower {prefix}collector.init_random_frames to {last_batch_end} or less"
        )
    _fail(
        prefix + "collector.total_frames",
        collector.total_frames,
        schedule.no_learning_reason(prefix)
        + "; "
        + ", or ".join(options or ["change these values"]),
    )


@dataclass
class TrainConfig:
    """A whole training run (``s3rl-train``)."""

    task: TaskConfig = field(default_factory=TaskConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    seed: int = 10
    # Several seeds in one process (trainer/multiseed.py): K independent agents, one batched
    # gradient step; `seed` is then unused (each seed's sub-run records its own).
    seeds: list[int] | None = None
    device: str = "cpu"
    # torch intra-op threads; 0 keeps torch's default. One is the robust choice on 2 shared
    # cores: two threads stall whenever another process runs (docs/benchmarks.md).
    threads: int = 1
    # torch.compile of the loss (the package's ReLU keeps it fast on CPU, docs/objectives.md).
    compile: bool = True
    save_interval: int = 4  # epochs between checkpoints (and one at the end)
    resume: str | None = None  # a run directory to continue; "auto" (recipe): its own, if any

    def check(self, path: str = "") -> None:
        prefix = f"{path}." if path else ""
        _check_finite(self, path)
        for name in ("task", "algo", "network", "collector", "eval", "logger"):
            getattr(self, name).check(prefix + name)
        _check_choice(prefix + "device", self.device, DEVICES)
        _check_range(prefix + "threads", self.threads, 0)
        _check_range(prefix + "save_interval", self.save_interval, 1)
        if self.compile and self.device == "cpu":
            _check_cpp_compiler(prefix + "compile")
        if self.seeds is not None:
            self._check_seeds(prefix + "seeds")
        if self.collector.frames_per_epoch % self.collector.frames_per_batch:
            _fail(
                prefix + "collector.frames_per_epoch",
                self.collector.frames_per_epoch,
                f"must be a multiple of collector.frames_per_batch "
                f"({self.collector.frames_per_batch})",
            )
        self._check_contrastive_label(prefix)
        _check_learns(self.collector, self.algo, prefix)

    def _check_contrastive_label(self, prefix: str) -> None:
        path = prefix + "algo.contrastive_cfg.label"
        label = self.algo.contrastive_cfg.label
        if label == "binary":
            return
        if not self.algo.contrastive:
            _fail(path, label, "a graded label needs the contrastive phase (algo.contrastive=true)")
        if label == "margin" and get_task(self.task.name).margin_rule is None:
            having = sorted({t.family for t in map(get_task, task_names()) if t.margin_rule})
            _fail(
                path,
                label,
                f"task {self.task.name} exposes no margin (the {' and '.join(having)} tasks do); "
                "use binary or cost_to_go",
            )

    def _check_seeds(self, path: str) -> None:
        seeds = list(self.seeds)
        if not seeds:
            _fail(path, seeds, "must hold at least one seed (or be null: one run with `seed`)")
        if any(isinstance(s, bool) or not isinstance(s, int) for s in seeds):
            _fail(path, seeds, "must be integers")
        if len(set(seeds)) != len(seeds):
            _fail(path, seeds, "must be distinct (a repeated seed would train the same run twice)")
        if self.algo.family != "sac":
            _fail(
                path,
                seeds,
                f"multi-seed training supports the SAC family only "
                f"({', '.join(n for n, f in ALGO_FAMILIES.items() if f == 'sac')}); "
                f"got algo.name={self.algo.name!r}: train its seeds as separate runs",
            )
        if self.algo.update_order != "joint":
            _fail(
                path,
                seeds,
                f"needs algo.update_order=joint (multi-seed training batches the joint update; "
                f"got {self.algo.update_order!r})",
            )


@dataclass
class EvalRunConfig:
    """``s3rl-eval``: evaluate a checkpoint."""

    checkpoint: str = MISSING
    episodes: int = 10
    num_envs: int = 2
    seed: int = 0
    max_steps: int | None = None  # None: the checkpoint's task's episode length
    video: bool = False
    video_path: str | None = None

    def check(self, path: str = "") -> None:
        _check_range("episodes", self.episodes, 1)
        _check_range("num_envs", self.num_envs, 1)
        if self.max_steps is not None:
            _check_range("max_steps", self.max_steps, 1)


def run_dir_name(seed: int, seeds: list[int] | None) -> str:
    """The seed part of a run's default directory: ``seed10``, or ``seeds10-20-30`` for a group."""
    return f"seeds{'-'.join(map(str, seeds))}" if seeds else f"seed{seed}"


def hydra_run_dir(resume: str | None, algo: str, task: str, seeds: str, now: str) -> str:
    """Where ``s3rl-train`` runs: ``outputs/<algo>/<task>/<seed10 | seeds10-20>/<time>``, or,
    for a resume, ``<run>/resumes/<time>`` (that invocation's Hydra files and log, beside the
    run it continues); ``${s3rl_run_dir:...}`` in configs/train.yaml."""
    if resume and resume != "auto":  # resume=auto runs in the command's own directory
        return str(Path(resume).expanduser() / "resumes" / now)
    return f"outputs/{algo}/{task}/{seeds}/{now}"


def episode_frames(task_name: str, episodes: int) -> int:
    """Frames in ``episodes`` whole episodes of a task: FSRL's ``episode_per_collect`` as a
    torchrl batch size (``${s3rl_episode_frames:${task.name},20}`` in ``experiment=paper``)."""
    _check_choice("task.name", task_name, tuple(task_names()))
    return int(episodes) * get_task(task_name).max_episode_steps


def lagrangian_for(algo_name: str, controller: str) -> str:
    """``controller`` for an algorithm with a Lagrange multiplier, ``none`` for the others
    (``${s3rl_lagrangian:${algo.name},learned}`` in ``experiment=safe``)."""
    _check_choice("algo.name", algo_name, ALGO_NAMES)
    return "none" if algo_name in UNCONSTRAINED_ALGOS else controller


def safe_cost_limit(task_name: str) -> float:
    """The limit ``experiment=safe`` trains a task at (``TaskSpec.safe_cost_limit``: the peers'
    benchmark limit where the registry has one, e.g. 25 for SafetyPointGoal1, else the paper's
    10); ``${s3rl_safe_cost_limit:${task.name}}``. A ``task.cost_limit=`` override still wins."""
    _check_choice("task.name", task_name, tuple(task_names()))
    return float(get_task(task_name).safe_cost_limit)


def safe_setting(task_name: str, name: str, default: Any) -> Any:
    """A task's own value of one setting of ``experiment=safe`` (``TaskSpec.safe``), else
    ``default``: ``${s3rl_safe_setting:${task.name},lagrangian_lr,3e-4}``."""
    _check_choice("task.name", task_name, tuple(task_names()))
    settings = get_task(task_name).safe
    if not hasattr(settings, name):
        _fail("s3rl_safe_setting", name, f"TaskSpec.safe has no setting {name!r}")
    value = getattr(settings, name)
    return default if value is None else value


def round_up(value: int, multiple: int) -> int:
    """``value`` rounded up to a multiple of ``multiple``: FSRL's epoch runs whole collects until
    ``step_per_epoch`` frames are reached (``${s3rl_round_up:10000,${collector.frames_per_batch}}``)."""
    return math.ceil(int(value) / int(multiple)) * int(multiple)


def register_configs() -> None:
    """Store the schemas (and one ``task`` option per registered task) in Hydra's ConfigStore,
    and the resolvers the YAMLs use: ``s3rl_run_name`` (default output directories),
    ``s3rl_episode_frames`` and ``s3rl_round_up`` (``experiment=paper``'s collects and epochs),
    ``s3rl_lagrangian`` (``experiment=safe``'s controller, for constrained algorithms only),
    ``s3rl_safe_cost_limit`` and ``s3rl_safe_setting`` (``experiment=safe``'s per-task limit
    and settings, from the task registry)."""
    OmegaConf.register_new_resolver("s3rl_run_name", run_dir_name, replace=True)
    OmegaConf.register_new_resolver("s3rl_run_dir", hydra_run_dir, replace=True)
    OmegaConf.register_new_resolver("s3rl_episode_frames", episode_frames, replace=True)
    OmegaConf.register_new_resolver("s3rl_round_up", round_up, replace=True)
    OmegaConf.register_new_resolver("s3rl_lagrangian", lagrangian_for, replace=True)
    OmegaConf.register_new_resolver("s3rl_safe_cost_limit", safe_cost_limit, replace=True)
    OmegaConf.register_new_resolver("s3rl_safe_setting", safe_setting, replace=True)
    cs = ConfigStore.instance()
    cs.store(name="train_schema", node=TrainConfig)
    cs.store(name="eval_schema", node=EvalRunConfig)
    for name in task_names():
        cs.store(
            group="task", name=name, node=TaskConfig(name=name, cost_limit=get_task(name).cost_limit)
        )


def validate(cfg: DictConfig | TrainConfig, schema: type = TrainConfig) -> Any:
    """Turn a Hydra config into its dataclass and check every value; raise ``ConfigError``."""
    if isinstance(cfg, DictConfig):
        merged = OmegaConf.merge(OmegaConf.structured(schema), cfg)
        obj = OmegaConf.to_object(merged)
    else:
        obj = cfg
    obj.check()
    if isinstance(obj, TrainConfig) and obj.eval.max_steps is None:
        obj.eval.max_steps = get_task(obj.task.name).max_episode_steps
    return obj


def to_container(obj: Any) -> dict:
    """A dataclass config as plain dicts (for JSON and checkpoints)."""
    if is_dataclass(obj):
        return {f.name: to_container(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, list | tuple):
        return [to_container(v) for v in obj]
    return obj
