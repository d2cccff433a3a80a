"""Typed configuration of a training run: one dataclass per component, stored in Hydra's
ConfigStore so that every YAML under ``configs/`` is type-checked against it.

The algorithm's part (``algo``) is its family's class (``s3rl_torchrl/algorithms/``:
``SACConfig``, ``DDPGConfig``, ``PPOConfig``), which the algorithm's YAML picks through its
registry entry (``/algo_defaults@_here_: <name>``). Types are checked by OmegaConf when Hydra
merges the YAMLs and overrides; values (ranges and choices) are checked by :func:`validate`,
which every entry point calls before it builds anything, so a bad override fails with the
field's name and what it accepts.

A config saved by an earlier version (a run's ``config.json``, a checkpoint's config) loads with
:func:`saved_config_node`: its ``algo`` held every family's fields then, and the fields its
family does not have are dropped; an option that has left the package is dropped at its default
and refused at any other value (see there).
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from s3rl_torchrl.algorithms.config import (
    AlgoConfig,
    ConfigError,
    check_choice,
    check_finite,
    check_range,
    drop_removed_options,
    fail,
)
from s3rl_torchrl.algorithms.registry import ALGORITHMS, family_of
from s3rl_torchrl.algorithms.schedule import collector_batch_frames
from s3rl_torchrl.envs import BATCHING_CHOICES, get_task, require_task_module, task_names
from s3rl_torchrl.modules import ACTIVATIONS
from s3rl_torchrl.trainer.presets import SAFE_SETTING_NAMES, safe_task_settings

__all__ = [
    "ConfigError",
    "TrainConfig",
    "register_configs",
    "saved_config_node",
    "saved_train_config",
    "to_container",
    "validate",
]

ALGO_NAMES = tuple(ALGORITHMS)
LOGGER_BACKENDS = ("csv", "tensorboard", "wandb", "mlflow", "none")
# backend -> (module it imports, the package extra that installs it)
LOGGER_PACKAGES = {
    "tensorboard": ("tensorboard", "tensorboard"),
    "wandb": ("wandb", "wandb"),
    "mlflow": ("mlflow", "mlflow"),
}
DEVICES = ("cpu", "cuda", "mps")
#: What ``s3rl-train`` returns to a sweeper, of the delivered policy's final evaluation (mean over
#: seeds): its reward (maximise), its cost (minimise), or both, for a two-objective study.
OBJECTIVES = ("reward", "cost", "reward_cost")
# The loggers whose log_video writes a video here (eval.video_interval): torchrl's MLflow logger
# needs torchcodec and a system FFmpeg, `none` logs nothing.
VIDEO_LOGGERS = ("csv", "tensorboard", "wandb")
# Seeds a run accepts: Gymnasium refuses negative seeds, and the seeds derived from a run's
# (its test envs' seed + 100000, the diagnostics' seed * 1000003 + epoch) must stay within
# torch's 64 bits; numpy's legacy range is the conventional one and keeps both.
SEED_MAX = 2**32 - 1


def check_seed(path: str, seed: Any) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= SEED_MAX:
        fail(path, seed, f"a seed must be an integer from 0 to {SEED_MAX} (2**32 - 1)")


def check_device(path: str, device: str) -> None:
    """The device must be one this torch build can use: fail here, not in the first step."""
    import torch

    check_choice(path, device, DEVICES)
    if device == "cuda" and not torch.cuda.is_available():
        build = "a CPU-only build" if torch.version.cuda is None else "a CUDA build"
        fail(
            path,
            device,
            f"this torch ({torch.__version__}, {build}) sees no CUDA device; use device=cpu, "
            "or install a CUDA build of torch on a machine with a GPU (docs/installation.md)",
        )
    if device == "mps" and not torch.backends.mps.is_available():
        fail(path, device, "this machine has no MPS device (Apple silicon); use device=cpu")


def _check_cpp_compiler(path: str) -> None:
    """torch.compile on CPU builds C++ kernels: fail here, not at the first gradient step."""
    from torch._inductor import config as inductor_config
    from torch._inductor.cpp_builder import get_cpp_compiler
    from torch._inductor.exc import InvalidCxxCompiler

    try:
        get_cpp_compiler()
    except InvalidCxxCompiler:
        tried = [cxx for cxx in inductor_config.cpp.cxx if cxx]
        fail(
            path,
            True,
            f"torch.compile on CPU needs a C++ compiler and none of {tried} runs (or set CXX); "
            "install one (Debian/Ubuntu: apt-get install g++) or pass compile=false",
        )


@dataclass
class TaskConfig:
    """Which task, and its per-episode cost limit d.

    Each ``task=<id>`` option of the ConfigStore carries the registry's default ``cost_limit``
    for that task (the paper's 10 for every task, Table 3); ``task.cost_limit=...`` overrides it.
    """

    name: str = MISSING
    cost_limit: float = 10.0

    def check(self, path: str) -> None:
        check_choice(f"{path}.name", self.name, tuple(task_names()))
        check_range(f"{path}.cost_limit", self.cost_limit, 0.0)
        try:  # an optional package the task needs (the Bullet tasks): fail before building
            require_task_module(get_task(self.name))
        except ImportError as err:
            fail(f"{path}.name", self.name, str(err))


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
                fail(f"{path}.{name}", list(sizes), "must be a non-empty list of sizes >= 1")
        check_choice(f"{path}.activation", self.activation, tuple(ACTIVATIONS))
        if not self.log_std_min < self.log_std_max:
            fail(f"{path}.log_std_min", self.log_std_min, "must be below log_std_max")


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
        check_range(f"{path}.num_envs", self.num_envs, 1)
        check_choice(f"{path}.batching", self.batching, BATCHING_CHOICES)
        check_range(f"{path}.frames_per_batch", self.frames_per_batch, self.num_envs)
        check_range(f"{path}.total_frames", self.total_frames, 1)
        check_range(f"{path}.init_random_frames", self.init_random_frames, 0)
        check_range(f"{path}.frames_per_epoch", self.frames_per_epoch, 1)


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
    # The delivered policy (trainer.evaluation.DeliveryCandidates; docs/recipes.md): 0 delivers
    # the last policy alone; K > 0 also keeps the policies of the last K epochs and, after
    # training, evaluates each on delivery_episodes fresh episodes and delivers the one with the
    # highest reward among those whose cost is at most delivery_cost_share x task.cost_limit
    # (none: the cheapest), evaluated again on final_episodes other episodes.
    delivery_epochs: int = 0
    delivery_episodes: int = 5
    delivery_cost_share: float = 1.0
    # Also evaluate every kept policy on final_episodes other episodes (the candidates'
    # report_reward / report_cost in final_eval.json), so that another picking rule's pick can be
    # read off the same run, reported on episodes it was not picked on. After the pick's own
    # evaluation: the run's other numbers are unchanged.
    delivery_report_all: bool = False
    # Exponential moving averages of the actor's weights over about h gradient steps each
    # (decay 1 - 1/h; hooks/policy_average.py), evaluated at every epoch's end (ema<h>/* columns)
    # and on the final episodes (final_eval.json's ema<h>), on test envs of their own. []: none.
    ema_horizons: list[int] = field(default_factory=list)
    # Every this many epochs, a video of one deterministic episode (eval.max_steps steps, unsafe
    # steps marked) through the logger's log_video (hooks/video.py, docs/video.md); 0: none.
    video_interval: int = 0

    def check(self, path: str) -> None:
        check_range(f"{path}.num_envs", self.num_envs, 1)
        check_range(f"{path}.episodes", self.episodes, 1)
        check_range(f"{path}.final_episodes", self.final_episodes, 1)
        check_range(f"{path}.delivery_epochs", self.delivery_epochs, 0)
        check_range(f"{path}.delivery_episodes", self.delivery_episodes, 1)
        check_range(
            f"{path}.delivery_cost_share", self.delivery_cost_share, 0.0, 1.0, low_inclusive=False
        )
        if self.max_steps is not None:
            check_range(f"{path}.max_steps", self.max_steps, 1)
        check_range(f"{path}.video_interval", self.video_interval, 0)
        horizons = list(self.ema_horizons)
        for horizon in horizons:
            check_range(f"{path}.ema_horizons", horizon, 1)
        if len(set(horizons)) != len(horizons):
            fail(f"{path}.ema_horizons", horizons, "must not repeat a horizon")


@dataclass
class LoggerConfig:
    """torchrl logger backend; CSV needs no server, W&B runs offline by default."""

    backend: str = "csv"
    project: str = "s3rl-torchrl"
    wandb_mode: str = "offline"
    progress_bar: bool = True

    def check(self, path: str) -> None:
        check_choice(f"{path}.backend", self.backend, LOGGER_BACKENDS)
        check_choice(f"{path}.wandb_mode", self.wandb_mode, ("offline", "online", "disabled"))
        module, extra = LOGGER_PACKAGES.get(self.backend, (None, None))
        if module is not None and importlib.util.find_spec(module) is None:
            fail(
                f"{path}.backend",
                self.backend,
                f"needs the '{module}' package: pip install -e \".[{extra}]\" "
                f"(or choose csv or none)",
            )


@dataclass
class DiagnosticsConfig:
    """Measurements added to each epoch's row (trainer hooks, ``s3rl_torchrl/hooks/``). They
    change nothing that is trained."""

    # The linear probes of the policy encoder: probe/accuracy, probe/auc (safe vs unsafe) and
    # probe/spearman, probe/r2 (a graded label); docs/results.md. experiment=paper turns them on.
    probes: bool = False
    # The SAC family's critics against recent returns and the actor's gradient per loss term:
    # critic/*, grad/* (docs/objectives.md, "Critic diagnostics"). No effect on other families.
    critics: bool = True


def _check_learns(collector: CollectorConfig, algo: AlgoConfig, prefix: str) -> None:
    """Refuse a run that would evaluate an untrained policy as if it were trained."""
    family = family_of(algo)
    schedule = family.schedule(collector, algo)
    if schedule.planned_gradient_steps(stop_at=1) > 0:
        return
    batch = collector_batch_frames(collector)

    def learns(**changes: int) -> bool:
        changed = CollectorConfig(**{**vars(collector), **changes})
        return family.schedule(changed, algo).planned_gradient_steps(stop_at=1) > 0

    options = []
    # The fewest whole batches that learn with the other values unchanged. Bounded: once past
    # init_random_frames and batch_size stored transitions (n-step holds back n_step frames
    # per env), every batch owes update_per_step * batch steps. (Only an off-policy schedule
    # can fail to learn: every on-policy batch owes ppo_epochs passes.)
    held_back = getattr(algo, "n_step", 1) * collector.num_envs
    start = max(collector.init_random_frames, algo.batch_size + held_back)
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
    fail(
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
    # The algorithm's family's config (algorithms/): S3RL's by default. Hydra's schema holds the
    # base class, which the algorithm's YAML turns into its family's.
    algo: AlgoConfig = field(default_factory=lambda: ALGORITHMS["s3rl"].config("s3rl"))
    network: NetworkConfig = field(default_factory=NetworkConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    diagnostics: DiagnosticsConfig = field(default_factory=DiagnosticsConfig)
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
    # What s3rl-train returns to a Hydra sweeper (e.g. Optuna's), from the final evaluation of
    # the policy the run delivers (recipes/train.py: sweep_objective); trains nothing else.
    objective: str = "reward"

    def check(self, path: str = "") -> None:
        prefix = f"{path}." if path else ""
        check_finite(self, path)
        check_choice(prefix + "algo.name", self.algo.name, ALGO_NAMES)
        family = family_of(self.algo)
        if type(self.algo) is not family.config:
            fail(
                prefix + "algo.name",
                self.algo.name,
                f"is a {family.name.upper()} algorithm, its config a {family.config.__name__} "
                f"(got a {type(self.algo).__name__}); choose it with algo={self.algo.name}",
            )
        for name in ("task", "algo", "network", "collector", "eval", "logger"):
            getattr(self, name).check(prefix + name)
        check_device(prefix + "device", self.device)
        check_seed(prefix + "seed", self.seed)
        check_range(prefix + "threads", self.threads, 0)
        check_range(prefix + "save_interval", self.save_interval, 1)
        check_choice(prefix + "objective", self.objective, OBJECTIVES)
        # Only the SAC family compiles its loss (DDPG and PPO are always eager): their runs
        # need no C++ compiler, whatever `compile` says.
        if self.compile and self.device == "cpu" and family.name == "sac":
            _check_cpp_compiler(prefix + "compile")
        if self.seeds is not None:
            self._check_seeds(prefix + "seeds")
        if self.collector.frames_per_epoch % self.collector.frames_per_batch:
            fail(
                prefix + "collector.frames_per_epoch",
                self.collector.frames_per_epoch,
                f"must be a multiple of collector.frames_per_batch "
                f"({self.collector.frames_per_batch})",
            )
        self._check_contrastive_label(prefix)
        _check_learns(self.collector, self.algo, prefix)
        if self.eval.video_interval and self.logger.backend not in VIDEO_LOGGERS:
            fail(
                prefix + "eval.video_interval",
                self.eval.video_interval,
                f"logs its video through the logger, and logger={self.logger.backend} logs "
                f"none; choose logger={', '.join(VIDEO_LOGGERS)} (docs/video.md)",
            )
        if self.eval.video_interval and self.seeds is not None:
            fail(
                prefix + "eval.video_interval",
                self.eval.video_interval,
                "is for single-seed runs; record a seed's video with s3rl-eval video=true",
            )
        if self.eval.ema_horizons and self.seeds is not None:
            fail(
                prefix + "eval.ema_horizons",
                list(self.eval.ema_horizons),
                "is for single-seed runs (seed=N, not seeds=[...])",
            )

    def _check_contrastive_label(self, prefix: str) -> None:
        path = prefix + "algo.contrastive_cfg.label"
        label = self.algo.contrastive_cfg.label
        if label == "binary":
            return
        if not self.algo.contrastive:
            fail(path, label, "a graded label needs the contrastive phase (algo.contrastive=true)")
        if label == "margin" and get_task(self.task.name).margin_rule is None:
            having = sorted({t.family for t in map(get_task, task_names()) if t.margin_rule})
            fail(
                path,
                label,
                f"task {self.task.name} exposes no margin (the {' and '.join(having)} tasks do); "
                "use binary or cost_to_go",
            )

    def _check_seeds(self, path: str) -> None:
        seeds = list(self.seeds)
        if not seeds:
            fail(path, seeds, "must hold at least one seed (or be null: one run with `seed`)")
        if any(isinstance(s, bool) or not isinstance(s, int) for s in seeds):
            fail(path, seeds, "must be integers")
        for index, seed in enumerate(seeds):
            check_seed(f"{path}[{index}]", seed)
        if len(set(seeds)) != len(seeds):
            fail(path, seeds, "must be distinct (a repeated seed would train the same run twice)")
        if not family_of(self.algo).seeds_in_one_process:
            able = [name for name, a in ALGORITHMS.items() if a.family.seeds_in_one_process]
            fail(
                path,
                seeds,
                f"multi-seed training supports the SAC family only ({', '.join(able)}); "
                f"got algo.name={self.algo.name!r}: train its seeds as separate runs",
            )
        if self.algo.update_order != "joint":
            fail(
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
        check_range("episodes", self.episodes, 1)
        check_range("num_envs", self.num_envs, 1)
        if self.max_steps is not None:
            check_range("max_steps", self.max_steps, 1)


def run_dir_name(seed: int, seeds: list[int] | None) -> str:
    """The seed part of a run's default directory: ``seed10``, or ``seeds10-20-30`` for a group."""
    return f"seeds{'-'.join(map(str, seeds))}" if seeds else f"seed{seed}"


def sweep_trial(sweeper: str, job_num: int) -> str:
    """What tells a sweep's jobs apart in their default directory beyond algo, task and seed:
    nothing under Hydra's basic sweeper (its jobs are known before any starts, and the launch
    checks refuse two that would share a directory), ``_trial<N>`` (the job's number) under a
    sweeper that chooses its jobs as it goes, such as Optuna's, whose trials share algo, task and
    seed; ``${s3rl_trial:${hydra.runtime.choices.hydra/sweeper},${hydra.job.num}}`` in
    configs/train.yaml."""
    return "" if sweeper == "basic" else f"_trial{job_num}"


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
    check_choice("task.name", task_name, tuple(task_names()))
    return int(episodes) * get_task(task_name).max_episode_steps


def lagrangian_for(algo_name: str, controller: str) -> str:
    """``controller`` for an algorithm with a Lagrange multiplier, ``none`` for the others
    (``${s3rl_lagrangian:${algo.name},learned}`` in ``experiment=safe`` and ``quick``). An
    unknown name is left to :func:`validate`, whose error lists the valid ones."""
    entry = ALGORITHMS.get(algo_name)
    return "none" if entry is not None and entry.lagrangian == "none" else controller


def safe_cost_limit(task_name: str) -> float:
    """The limit ``experiment=safe`` trains a task at: its own in the preset's table
    (``trainer/presets.py``: 25 for SafetyPointGoal1, OmniSafe's), else the task's default, the
    paper's 10; ``${s3rl_safe_cost_limit:${task.name}}``. A ``task.cost_limit=`` override wins."""
    check_choice("task.name", task_name, tuple(task_names()))
    own = safe_task_settings(task_name).cost_limit
    return float(get_task(task_name).cost_limit if own is None else own)


def safe_setting(task_name: str, name: str, default: Any) -> Any:
    """A task's own value of one setting of ``experiment=safe`` (its entry in
    ``trainer/presets.py:SAFE_TASK_SETTINGS``), else ``default``:
    ``${s3rl_safe_setting:${task.name},lagrangian_lr,3e-4}``."""
    check_choice("task.name", task_name, tuple(task_names()))
    if name not in SAFE_SETTING_NAMES:
        fail("s3rl_safe_setting", name, f"valid settings are {', '.join(SAFE_SETTING_NAMES)}")
    value = getattr(safe_task_settings(task_name), name)
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
    and settings, from its table: ``trainer/presets.py``), ``s3rl_trial`` (a search's trials in a
    sweep's default directories)."""
    OmegaConf.register_new_resolver("s3rl_run_name", run_dir_name, replace=True)
    OmegaConf.register_new_resolver("s3rl_trial", sweep_trial, replace=True)
    OmegaConf.register_new_resolver("s3rl_run_dir", hydra_run_dir, replace=True)
    OmegaConf.register_new_resolver("s3rl_episode_frames", episode_frames, replace=True)
    OmegaConf.register_new_resolver("s3rl_round_up", round_up, replace=True)
    OmegaConf.register_new_resolver("s3rl_lagrangian", lagrangian_for, replace=True)
    OmegaConf.register_new_resolver("s3rl_safe_cost_limit", safe_cost_limit, replace=True)
    OmegaConf.register_new_resolver("s3rl_safe_setting", safe_setting, replace=True)
    cs = ConfigStore.instance()
    # `algo` as the base class: each configs/algo/<name>.yaml turns it into its family's config
    # with its registry entry's values (`- /algo_defaults@_here_: <name>`).
    cs.store(name="train_schema", node=TrainConfig(algo=AlgoConfig()))
    cs.store(name="eval_schema", node=EvalRunConfig)
    for name, algorithm in ALGORITHMS.items():
        cs.store(group="algo_defaults", name=name, node=algorithm.config(name))
    for name in task_names():
        cs.store(
            group="task", name=name, node=TaskConfig(name=name, cost_limit=get_task(name).cost_limit)
        )


def _train_schema(algo: Any) -> DictConfig:
    """The typed node of a ``TrainConfig`` whose ``algo`` is ``algo``'s: a family's config
    already (a Hydra config), else the family its ``name`` registers."""
    if isinstance(algo, DictConfig) and issubclass(OmegaConf.get_type(algo), AlgoConfig):
        return OmegaConf.structured(TrainConfig(algo=AlgoConfig()))
    name = (algo or {}).get("name") if isinstance(algo, dict | DictConfig) else None
    family = family_of(name if isinstance(name, str) else "")
    return OmegaConf.structured(TrainConfig(algo=family.config(name=name)))


def saved_config_node(saved: dict) -> DictConfig:
    """The typed ``TrainConfig`` node of a saved config (a run's ``config.json``, a
    checkpoint's), written by this version or an earlier one:

    - ``algo`` becomes its family's config and the fields that family does not have are
      dropped: up to commit 8e0ee0c one class held every family's fields, so a PPO run saved
      ``n_step``, ``tau`` and ``alpha_*``, a SAC run ``ppo_epochs`` and ``exploration_noise``,
      a DDPG run ``update_order`` (always ``fsrl``) and the SAC critics' switches, none of
      which its family read;
    - a config without ``diagnostics`` (before the trainer hooks) ran the linear probes at
      every epoch, so they stay on: the resumed run logs the columns it logged;
    - a ``contrastive_cfg`` without ``phase_at`` (before 2026-11-28) ran each contrastive phase
      at the end of its interval, so it keeps ``end``: a resume keeps the run's schedule;
    - an option that has left the package (``algorithms.config.REMOVED_OPTIONS``) is dropped
      at its default, and refused (``ConfigError``, naming the last commit that had it) at
      any other value (``drop_removed_options``).
    """
    saved = dict(saved)
    algo = drop_removed_options(dict(saved.get("algo") or {}))
    family = family_of(algo.get("name", ""))
    kept = {f.name for f in fields(family.config)}
    saved["algo"] = {key: value for key, value in algo.items() if key in kept}
    saved.setdefault("diagnostics", {"probes": True})
    if isinstance(saved["algo"].get("contrastive_cfg"), dict):
        saved["algo"]["contrastive_cfg"] = {"phase_at": "end", **saved["algo"]["contrastive_cfg"]}
    return OmegaConf.merge(_train_schema(saved["algo"]), saved)


def saved_train_config(saved: dict) -> TrainConfig:
    """A saved config as this version's :class:`TrainConfig` (:func:`saved_config_node`),
    not validated: the values the run ran with."""
    return OmegaConf.to_object(saved_config_node(saved))


def validate(cfg: DictConfig | TrainConfig, schema: type = TrainConfig) -> Any:
    """Turn a Hydra config into its dataclass and check every value; raise ``ConfigError``."""
    if isinstance(cfg, DictConfig):
        if schema is TrainConfig:
            merged = OmegaConf.merge(_train_schema(cfg.get("algo")), cfg)
        else:
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
