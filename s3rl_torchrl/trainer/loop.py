"""The training loop of every algorithm (S3RL, SAC-Lag, DDPG-Lag, PPO-Lag, ...): collect,
store, update lambda, update, evaluate.

Read top to bottom: :func:`train` builds everything from a :class:`TrainConfig`, then runs one
iteration per collected batch:

1. store the batch as the algorithm's update schedule says (algorithms/schedule.py; off-policy:
   n-step transitions into the replay buffer; on-policy: the advantages (GAE) of the batch,
   which replaces the previous one, and its labelled states into a FIFO for the contrastive
   phase);
2. hand the costs of the training episodes that ended in the batch to the Lagrangian: with
   ``algo.lagrangian_cadence=collect`` (FSRL, the paper) lambda updates once now, from their
   mean, before this collect's gradient steps (none ended: no update); with ``step``
   (OmniSafe) they join the window of the last ``algo.lagrangian_window`` episodes;
3. run the gradient steps the schedule owes for the batch (off-policy: ``update_per_step`` per
   collected frame after the warm-up; on-policy: ``ppo_epochs`` passes of minibatches), each
   the algorithm's ``update`` (critics, actor, alpha for SAC, then the targets), followed under
   cadence ``step`` by one lambda update from the window, and every ``T`` gradient steps the
   contrastive phase on the policy encoder;
4. at each epoch's end: evaluate deterministically, log, checkpoint every ``save_interval``.

What a run measures or stores besides training comes from hooks (``s3rl_torchrl/hooks/``),
which the config switches on and which the loop calls at five points: after each collect,
after each gradient step, after each evaluation (columns of the epoch's row), at each epoch's
end and after the final evaluation (entries of ``final_eval.json``;
:meth:`Trainer.register_op`, as torchrl's trainer offers).

Interrupts (Ctrl-C, SIGTERM) stop between two gradient steps; a checkpoint is written and the
run can go on with ``resume=<run dir>``: pending gradient steps and the epoch's end are done
first, so the resumed run ends with the same counters as an uninterrupted one.
"""

from __future__ import annotations

import json
import math
import random
import signal
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tqdm.auto import tqdm

from s3rl_torchrl.algorithms import Agent
from s3rl_torchrl.envs.state import env_snapshot, restore_env
from s3rl_torchrl.hooks import (
    HOOK_POINTS,
    CriticDiagnostics,
    EvalVideo,
    GradedLabels,
    LinearProbes,
    PolicyAverage,
    TrainerHook,
)
from s3rl_torchrl.trainer.builders import (
    build_agent,
    build_envs,
    build_replay_buffer,
    build_updates,
    set_torch_threads,
)
from s3rl_torchrl.trainer.checkpoint import (
    capture_rng_state,
    check_writable,
    restore_rng_state,
    save_checkpoint,
)
from s3rl_torchrl.trainer.collector import ResumableCollector
from s3rl_torchrl.trainer.config import TrainConfig, to_container
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy
from s3rl_torchrl.trainer.evaluation import (
    BestFeasible,
    DeliveryCandidates,
    EvalResult,
    RandomPolicy,
    constraint_verdict,
    evaluate,
    format_table,
    pick_delivered,
)
from s3rl_torchrl.trainer.metrics import (
    CONFIG_FILE,
    FINAL_EVAL_FILE,
    RunMetrics,
    ensure_new_run_dir,
    make_torchrl_logger,
)
from s3rl_torchrl.trainer.resume import Resume
from s3rl_torchrl.trainer.run_lock import RunLock

CONTRASTIVE_DIAGNOSTICS = (
    "loss_infonce",
    "pos_similarity",
    "neg_similarity",
    "accuracy",
    "mi_lower_bound",
)
BEST_CHECKPOINT = "best"  # checkpoints/best: FSRL's best-feasible policy (evaluation.BestFeasible)
DELIVERED_CHECKPOINT = "delivered"  # checkpoints/delivered: eval.delivery_epochs' pick


@dataclass
class Counters:
    """Progress of a run; checkpointed, and equal after a resume to an uninterrupted run's."""

    frames: int = 0
    grad_steps: int = 0
    epochs: int = 0  # completed epochs (evaluated, logged)
    episodes: int = 0  # finished training episodes
    lagrangian_updates: int = 0
    contrastive_phases: int = 0
    contrastive_skipped: int = 0
    pending_updates: float = 0.0  # gradient steps owed to the frames collected so far


@dataclass
class TrainResult:
    run_dir: Path
    status: str  # "finished" or "interrupted"
    counters: Counters
    final_eval: EvalResult | None = None
    history: list[dict[str, Any]] = field(default_factory=list)
    exit_status: int = 0  # the command's (StopRequest.exit_status when interrupted)


class StopRequest:
    """Set by SIGINT/SIGTERM (or a callback): the loop stops at the next safe point."""

    def __init__(self) -> None:
        self.requested = False
        self.signum: int | None = None  # the signal that asked for the stop (None: a callback)
        self._previous: dict[int, Any] = {}

    def __call__(self, signum=None, frame=None) -> None:
        self.requested = True
        if signum is not None and self.signum is None:
            self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        """The status a command stopped this way exits with: the shell's 128 + the signal's
        number (130 for Ctrl-C, 143 for SIGTERM), so that ``s3rl-train ... && next`` does not
        go on with an unfinished run; 1 for a stop without a signal."""
        return 128 + self.signum if self.signum is not None else 1

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._previous[sig] = signal.signal(sig, self)
            except ValueError:  # not the main thread (e.g. some launchers): no handler
                pass

    def uninstall(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()


def compile_loss(fn: Callable) -> Callable:
    """``torch.compile`` for a loss module or one of its methods.

    ``isolate_recompiles``: torchrl's and tensordict's forward wrappers are code shared by every
    loss; without it their compiled entries pile up across compiled losses (8 at most, then
    eager) and are checked one after the other on each call.

    No guards on the modules' Python attributes (``skip_guard_on_all_nn_modules_unsafe``):
    checking them took 0.5 ms of a 4.7 ms gradient step (benchmarks/results/archive/2026-11-24/guard_filter.json).
    What changes during training reaches the compiled code anyway: parameters, buffers, lambda
    and log alpha are tensors read at each call (tensor and global guards, grad mode included,
    stay). What it no longer sees is a Python attribute of a loss or network reassigned after
    the first call (e.g. ``loss.fixed_alpha = ...``, a module swapped in): rebuild the loss, or
    call ``torch._dynamo.reset()``, after such a change.

    No guard on the length of tensordict's memo of type checks (``_TENSORCLASS_MEMO``) either:
    it grows whenever tensordict checks a type for the first time, e.g. ``tuple`` in the first
    eager ``vmap`` (the critic diagnostics' at the first epoch's end). The loss then recompiled,
    and every later step checked both entries' guards: 6.0 instead of 4.7 ms per step of the
    paper's recipe. No result depends on that length.
    """
    return torch.compile(
        fn, isolate_recompiles=True, options={"guard_filter_fn": _compiled_loss_guards}
    )


def _compiled_loss_guards(entries) -> list[bool]:
    """The guards :func:`compile_loss` keeps (its docstring says which it drops, and why)."""
    keep = torch.compiler.skip_guard_on_all_nn_modules_unsafe(entries)
    return [kept and "_TENSORCLASS_MEMO" not in entry.name for kept, entry in zip(keep, entries)]


def _tensordict(saved: dict[str, Any]) -> TensorDict:
    """A tensordict saved as ``{"data": td.to_dict(), "batch_size": [...]}``."""
    return TensorDict(saved["data"], batch_size=saved["batch_size"])


def seed_everything(seed: int) -> None:
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)


class Trainer:
    """Holds a run's components; :meth:`run` is the loop. Build it with :func:`train`.

    With ``cfg.resume`` the run continues from its checkpoint: ``trainer/resume.py`` reads and
    checks it before anything is built (:meth:`Resume.read
    <s3rl_torchrl.trainer.resume.Resume.read>`) and restores it once everything is
    (:meth:`Resume.restore <s3rl_torchrl.trainer.resume.Resume.restore>`).

    ``hooks`` (name -> :class:`~s3rl_torchrl.hooks.TrainerHook`) are registered after the
    hooks the config switches on, before a resumed run restores their state;
    ``on_epoch_end(trainer, row)`` is an ``"epoch_end"`` op registered last.
    """

    def __init__(
        self,
        cfg: TrainConfig,
        run_dir: str | Path,
        on_epoch_end: Callable[[Trainer, dict[str, Any]], None] | None = None,
        hooks: dict[str, TrainerHook] | None = None,
    ) -> None:
        self.cfg = cfg
        self.stop = StopRequest()
        # A resume's checkpoint, read, verified and checked against cfg before anything is
        # built or written (resume.py); it names the run directory.
        resume = Resume.read(cfg) if cfg.resume else None
        self.run_dir = resume.run_dir if resume is not None else Path(run_dir)
        self.run_lock = _take_run_dir(self.run_dir, new=resume is None)
        labels = self._build()
        self._register_hooks(labels, hooks, on_epoch_end)
        if resume is not None:
            resume.restore(self)  # the interrupted run's state; its files cut back to it
        else:
            (self.run_dir / CONFIG_FILE).write_text(json.dumps(to_container(cfg), indent=2))
        logger = make_torchrl_logger(
            cfg.logger.backend,
            self.run_dir,
            exp_name=f"{cfg.algo.name}_{cfg.task.name}_seed{cfg.seed}",
            project=cfg.logger.project,
            wandb_mode=cfg.logger.wandb_mode,
        )
        self.metrics = RunMetrics(self.run_dir, logger, resume=resume is not None)
        self.history: list[dict[str, Any]] = []

    def _build(self) -> GradedLabels | None:
        """The run's components, seeded, and its progress at the start of a run; returns the
        graded labels' hook, if the run stores a label."""
        cfg = self.cfg
        set_torch_threads(cfg.threads)
        seed_everything(cfg.seed)
        # A graded safety label stored with every step, when the contrastive phase contrasts
        # one or the probes measure one (hooks/labels.py); the margin is read by the env.
        labels = GradedLabels.for_run(cfg.algo, cfg.diagnostics.probes)
        self.train_env, self.test_env = build_envs(cfg, labels)
        # Off-policy: the replay buffer; on-policy: the FIFO of recent labelled states that the
        # contrastive phase and the probes sample (builders.build_replay_buffer).
        self.replay_buffer = build_replay_buffer(cfg.algo)
        # torch.compile of the SAC family's loss (its forward and, through AOTAutograd, its
        # backward); the optimiser and target steps stay eager (fused Adam, one foreach lerp).
        # The first steps pay the compile time (docs/benchmarks.md says when it pays off).
        self.agent: Agent = build_agent(
            cfg, self.train_env, self.replay_buffer, compile_loss if cfg.compile else None
        )
        # What the algorithm's update schedule stores and samples (algorithms/schedule.py).
        self.updates = build_updates(cfg, self.agent, self.replay_buffer, labels)
        self.schedule = self.updates.schedule
        self.counters = Counters()
        self.best = BestFeasible()
        epochs = cfg.eval.delivery_epochs
        self.delivery = DeliveryCandidates(epochs) if epochs else None  # eval.delivery_epochs
        # The collector and, until it is built on resume, the checkpoint's collector state.
        self._collector: ResumableCollector | None = None
        self._resume_collector: dict[str, Any] | None = None
        self._train_episodes: list[tuple[float, float]] = []  # (reward, cost) this epoch
        self._last_losses: dict[str, torch.Tensor] = {}
        self._last_contrastive: dict[str, float] = {}
        # Why a resume cannot continue the interrupted run exactly (None: it can, or new run).
        self.inexact_resume: str | None = None
        return labels

    def _register_hooks(
        self,
        labels: GradedLabels | None,
        hooks: dict[str, TrainerHook] | None,
        on_epoch_end: Callable[[Trainer, dict[str, Any]], None] | None,
    ) -> None:
        """The hooks the config asks for (hooks/; each registers its ops and its state), then
        ``hooks``, then ``on_epoch_end``."""
        cfg = self.cfg
        self._ops: dict[str, list[Callable]] = {point: [] for point in HOOK_POINTS}
        self._hooks: dict[str, TrainerHook] = {}
        if labels is not None:
            labels.register(self, "labels")
        if cfg.diagnostics.probes:
            LinearProbes(self.replay_buffer, self.agent.actor, labels, cfg.seed).register(
                self, "probes"
            )
        if cfg.diagnostics.critics and CriticDiagnostics.supports(self.agent.loss):
            CriticDiagnostics(
                self.agent.loss, self.replay_buffer, cfg.algo.gamma, cfg.seed
            ).register(self, "critic_diagnostics")
        if cfg.eval.video_interval:
            EvalVideo.for_run(cfg).register(self, "video")
        if cfg.eval.ema_horizons:
            PolicyAverage.for_run(cfg, self.agent.actor, evaluate).register(self, "policy_average")
        for name, hook in (hooks or {}).items():
            hook.register(self, name)
        if on_epoch_end is not None:
            self.register_op("epoch_end", on_epoch_end)

    # ----------------------------------------------------------------------------- hooks
    def register_op(self, point: str, op: Callable) -> None:
        """Call ``op`` at ``point`` (one of ``hooks.HOOK_POINTS``; what it takes and returns:
        ``hooks/base.py``), after the ops registered before it."""
        if point not in self._ops:
            raise ValueError(f"Unknown hook point {point!r}; valid are {', '.join(HOOK_POINTS)}.")
        self._ops[point].append(op)

    def register_module(self, name: str, module: TrainerHook) -> None:
        """Keep ``module``'s state in the checkpoint under ``name``."""
        if name in self._hooks:
            raise ValueError(f"a hook named {name!r} is registered already")
        self._hooks[name] = module

    # ----------------------------------------------------------------------------- the loop
    def run(self) -> TrainResult:
        cfg, c = self.cfg, self.counters
        self.stop.install()
        progress = tqdm(
            total=cfg.collector.total_frames,
            initial=c.frames,
            unit="frame",
            disable=not cfg.logger.progress_bar,
            dynamic_ncols=True,
        )
        collector = None
        try:
            # Built before anything else runs, so that a resumed run can put its envs and
            # carrier back first (_start_collector); None when no frame is left to collect.
            collector = self._start_collector()
            # A resumed run first pays what the interrupted one owed for its last batch.
            if not self._finish_batch():
                return self._interrupted(progress)
            for batch in collector if collector is not None else []:
                c.frames += batch.numel()
                self._store(batch)
                self._update_lagrangian(batch)
                c.pending_updates += self._updates_owed(batch.numel())
                progress.update(batch.numel())
                if not self._finish_batch():
                    return self._interrupted(progress)
                progress.set_postfix(self._progress_postfix(), refresh=False)
            final = self._saved_final_evaluation() or self._final_evaluation()
            return TrainResult(self.run_dir, "finished", c, final, self.history)
        finally:
            if collector is not None:
                # A shut-down collector has no carrier: keep what a later save() needs.
                self._resume_collector, self._collector = self._collector_state(), None
                collector.shutdown()
            progress.close()
            self.metrics.close()
            self.stop.uninstall()
            self.run_lock.release()

    def _finish_batch(self) -> bool:
        """Gradient steps owed, then the epoch's end if the batch closed one. False: stopped."""
        while self.counters.pending_updates >= 1.0:
            if self.stop.requested:
                return False
            self._gradient_step()
        if self._epochs_due() > self.counters.epochs:
            self._end_epoch()
        return not self.stop.requested or self.counters.frames >= self.cfg.collector.total_frames

    def _epochs_due(self) -> int:
        """Epochs the frames so far have closed. The run's last frames close a last, shorter
        epoch, so every run ends with a metrics row and a checkpoint (even one shorter than an
        epoch)."""
        frames, collector = self.counters.frames, self.cfg.collector
        if frames >= collector.total_frames:
            return math.ceil(frames / collector.frames_per_epoch)
        return frames // collector.frames_per_epoch

    # ----------------------------------------------------------------------------- steps
    def _start_collector(self) -> ResumableCollector | None:
        """The training collector, for the frames left; on resume, the envs' state and the
        carrier of the interrupted run are put back, so that the same episodes go on."""
        if self.cfg.collector.total_frames <= self.counters.frames:
            return None
        saved = self._resume_collector
        if saved is None:
            self._collector = self._make_collector()
            return self._collector
        # Building the collector resets the envs and may run the policy once: nothing of it
        # is kept, so the random streams are put back as the checkpoint left them.
        rng = capture_rng_state()
        collector = self._make_collector()
        restore_rng_state(rng)
        restore_env(self.train_env, saved["train_env"])
        collector.load_carrier(_tensordict(saved["carrier"]))
        self._collector, self._resume_collector = collector, None
        return collector

    def _make_collector(self) -> ResumableCollector:
        cfg, c = self.cfg, self.counters
        remaining = cfg.collector.total_frames - c.frames
        return ResumableCollector(
            self.train_env,
            self.agent.policy,  # DDPG: the actor with exploration noise
            frames_per_batch=cfg.collector.frames_per_batch,
            total_frames=remaining,
            init_random_frames=max(0, self.schedule.warmup_frames() - c.frames),
            device=cfg.device,
        )

    def _store(self, batch: TensorDictBase) -> None:
        for op in self._ops["after_collect"]:  # hooks: a graded label, the recent episodes
            batch = op(batch)
        self.updates.store(batch)

    def _update_lagrangian(self, batch: TensorDictBase) -> None:
        """Record the batch's finished episodes and hand their costs to the Lagrangian, which
        updates lambda now (cadence collect) or after each gradient step (cadence step)."""
        done = batch["next", "done"].squeeze(-1)
        episode_costs = batch["next", "episode_cost"][done]  # [episodes, m]
        if done.any():
            rewards = batch["next", "episode_reward"][done].sum(-1)
            self._train_episodes.extend(zip(rewards.tolist(), episode_costs.sum(-1).tolist()))
            self.counters.episodes += int(done.sum())
        updater = self.agent.lagrangian
        if updater is None:
            return
        mean_cost = updater.observe(episode_costs, self.counters.frames)
        self.counters.lagrangian_updates = updater.controller.num_updates
        if mean_cost is not None:
            # One row per batch, also under cadence step: J as the controller sees it now and
            # lambda before this batch's gradient steps.
            self.metrics.log_scalars(
                {
                    "lagrangian/episode_cost": float(sum(mean_cost)),
                    "lagrangian/value": self._lagrangian_value(),
                },
                step=self.counters.frames,
            )

    def _updates_owed(self, frames: int) -> float:
        # The schedule's rule, shared with the config check that refuses runs which would never
        # learn (off-policy: no learning from the uniform-random warm-up frames alone, torchrl's
        # and the SOTA scripts' habit; FSRL has no random warm-up, docs/objectives.md).
        return self.updates.owed(self.counters.frames, frames)

    def _update(self, batch: TensorDictBase) -> TensorDictBase:
        """One gradient step of the algorithm (its family's, algorithms/); the detached losses."""
        return self.agent.update(batch)

    def _gradient_step(self) -> None:
        self._after_gradient_step(self._update(self.updates.sample()))

    def _after_gradient_step(self, losses: TensorDictBase) -> None:
        """Counters, last losses, lambda under cadence step, every ``T`` steps the contrastive
        phase (at the start or the end of each interval: ``contrastive_cfg.phase_at``), then the
        hooks (shared with the multi-seed trainer, whose gradient steps are
        batched over seeds)."""
        agent = self.agent
        self.counters.grad_steps += 1
        self.counters.pending_updates -= 1.0
        self._last_losses = dict(losses.items())
        if agent.lagrangian is not None and agent.lagrangian.after_gradient_step():
            self.counters.lagrangian_updates = agent.lagrangian.controller.num_updates

        phase = agent.contrastive
        if phase is not None and self.cfg.algo.contrastive_cfg.phase_due(self.counters.grad_steps):
            stats = phase.run()
            if stats is None:
                self.counters.contrastive_skipped += 1
            else:
                self.counters.contrastive_phases += 1
                self._last_contrastive = stats
        for op in self._ops["after_update"]:
            op(losses)

    def _end_epoch(self) -> None:
        cfg, c = self.cfg, self.counters
        c.epochs += 1
        start = time.perf_counter()
        result = evaluate(self.test_env, self.agent.actor, cfg.eval.episodes, cfg.eval.max_steps)
        if self.agent.lagrangian is not None:  # algo.lagrangian_eval_window: part of lambda's J
            self.agent.lagrangian.observe_evaluation([[cost] for cost in result.episode_costs])
        if self.best.update(
            result.reward_mean, result.cost_mean, cfg.task.cost_limit, c.epochs, c.frames
        ):
            self._save_best()
        if self.delivery is not None:
            self.delivery.add(c.epochs, c.frames, self.agent.actor)
        row = self._epoch_row(result, time.perf_counter() - start)
        for op in self._ops["after_evaluation"]:  # hooks: probes, critic diagnostics
            row.update(op(row))
        self.metrics.log_epoch(row)
        self.history.append(row)
        self._train_episodes.clear()
        last = c.frames >= cfg.collector.total_frames
        if c.epochs % cfg.save_interval == 0 or last:
            self.save()
        for op in self._ops["epoch_end"]:
            op(self, row)

    def _epoch_row(self, result: EvalResult, eval_seconds: float) -> dict[str, Any]:
        c = self.counters
        episodes = self._train_episodes
        nan = float("nan")
        row: dict[str, Any] = {
            "frames": c.frames,
            "epoch": c.epochs,
            "grad_steps": c.grad_steps,
            "train/episodes": len(episodes),
            "train/reward": float(np.mean([r for r, _ in episodes])) if episodes else nan,
            "train/cost": float(np.mean([k for _, k in episodes])) if episodes else nan,
            "lagrangian": self._lagrangian_value(),
            "eval/reward": result.reward_mean,
            "eval/reward_std": result.reward_std,
            "eval/cost": result.cost_mean,
            "eval/cost_std": result.cost_std,
            "eval/length": result.length_mean,
            "eval/safe_occupancy": result.safe_occupancy,
            "eval/seconds": eval_seconds,
        }
        for key in self.agent.log_keys:
            value = self._last_losses.get(key)
            row[f"train/{key}"] = float(value.float().mean()) if value is not None else nan
        for key in CONTRASTIVE_DIAGNOSTICS:
            row[f"contrastive/{key}"] = float(self._last_contrastive.get(key, nan))
        return row

    def _progress_postfix(self) -> dict[str, str]:
        last = self.history[-1] if self.history else {}
        return {
            "reward": f"{last.get('eval/reward', float('nan')):.1f}",
            "cost": f"{last.get('eval/cost', float('nan')):.1f}",
            "lambda": f"{self._lagrangian_value():.3f}",
        }

    def _lagrangian_value(self) -> float:
        """Sum of lambda over the costs; 0 for unconstrained runs (torchrl's DDPGLoss has none)."""
        lagrangian = getattr(self.agent.loss, "lagrangian", None)
        return float(lagrangian.sum()) if lagrangian is not None and lagrangian.numel() else 0.0

    def _saved_final_evaluation(self) -> EvalResult | None:
        """A finished run resumed without more frames: its ``final_eval.json`` stands (the same
        weights evaluated again would give other episodes); printed, not recomputed."""
        path = self.run_dir / FINAL_EVAL_FILE
        if self.cfg.resume is None or self._collector is not None or not path.is_file():
            return None
        saved = json.loads(path.read_text())
        # The last policy's statistics, without the other policies' (best_feasible, delivered,
        # a hook's) entries beside them.
        result = EvalResult(**{f.name: saved[f.name] for f in fields(EvalResult) if f.name in saved})
        label = f"{self.cfg.algo.name} {self.cfg.task.name} seed {self.cfg.seed}"
        table = format_table(
            {label: result},
            f"Final evaluation (saved in {path}, not recomputed): {result.episodes} episodes",
            grad_steps={label: self.counters.grad_steps},
        )
        verdict = constraint_verdict(
            result.cost_mean, self.cfg.task.cost_limit, self.counters.frames
        )
        print(f"\n{table}\n\n{verdict}\n\nRun directory: {self.run_dir}\n")
        return result

    def _final_evaluation(self) -> EvalResult:
        """The last policy's evaluation and, beside it, the best-feasible checkpoint's
        (``final_eval.json``: the last policy's at the top level, the other under
        ``best_feasible``), then the result table."""
        cfg, c = self.cfg, self.counters
        episodes, max_steps = cfg.eval.final_episodes, cfg.eval.max_steps
        result = evaluate(self.test_env, self.agent.actor, episodes, max_steps)
        label = f"{cfg.algo.name} {cfg.task.name} seed {cfg.seed}"
        rows = {label: result}
        steps = {label: c.grad_steps}
        saved = result.to_dict()
        best_dir = self.run_dir / "checkpoints" / BEST_CHECKPOINT
        if self.best.epoch and best_dir.is_dir():
            best_actor, _ = load_policy(best_dir)
            best = evaluate(self.test_env, best_actor, episodes, max_steps)
            feasible = self.best.cost <= cfg.task.cost_limit
            rows[
                f"best-{'feasible' if feasible else 'infeasible'} checkpoint (epoch "
                f"{self.best.epoch}, {self.best.frames} frames; FSRL's rule)"
            ] = best
            saved["best_feasible"] = {**best.to_dict(), **asdict(self.best), "feasible": feasible}
        if self.delivery is not None and self.delivery.candidates:
            delivered, record, policy = self._delivered_evaluation(episodes, max_steps)
            self._save_delivered(policy, record)
            rows[
                f"delivered policy (epoch {record['epoch']}, {record['frames']} frames; picked "
                f"among the last {len(record['candidates'])} epochs' policies; "
                f"checkpoints/{DELIVERED_CHECKPOINT})"
            ] = delivered
            saved["delivered"] = {**delivered.to_dict(), **record}
        for op in self._ops["final_evaluation"]:  # hooks: the policy averages
            for name, extra in op(episodes, max_steps).items():
                rows[name] = extra
                saved[name] = extra.to_dict()
        Path(self.run_dir / FINAL_EVAL_FILE).write_text(json.dumps(saved, indent=2) + "\n")
        if cfg.eval.random_baseline:
            rows["random policy (reference)"] = evaluate(
                self.test_env, RandomPolicy(self.test_env), episodes, max_steps
            )
        title = f"Final evaluation: {episodes} deterministic episodes"
        table = format_table(rows, title, grad_steps=steps)
        verdict = constraint_verdict(result.cost_mean, cfg.task.cost_limit, c.frames)
        print(f"\n{table}\n\n{verdict}\n\nRun directory: {self.run_dir}\n")
        return result

    def _delivered_evaluation(
        self, episodes: int, max_steps: int | None
    ) -> tuple[EvalResult, dict[str, Any], torch.nn.Module]:
        """``eval.delivery_epochs``: each kept policy evaluated on ``eval.delivery_episodes``
        fresh episodes, the pick (:func:`pick_delivered`) evaluated again on ``episodes``
        others, so that the reported numbers are not those it was picked on. Returns that
        evaluation, its record (``final_eval.json``'s ``delivered``) and the picked policy."""
        cfg = self.cfg
        limit = cfg.eval.delivery_cost_share * cfg.task.cost_limit
        candidates, policies, results = [], [], []
        for candidate, policy in self.delivery.policies(self.agent.actor):
            candidates.append(candidate)
            policies.append(policy)
            results.append(evaluate(self.test_env, policy, cfg.eval.delivery_episodes, max_steps))
        index, feasible = pick_delivered(results, limit)
        delivered = evaluate(self.test_env, policies[index], episodes, max_steps)
        # eval.delivery_report_all: every candidate on other episodes too, after the pick's own.
        reports = (
            [evaluate(self.test_env, policy, episodes, max_steps) for policy in policies]
            if cfg.eval.delivery_report_all
            else None
        )
        record = {
            "epoch": candidates[index]["epoch"],
            "frames": candidates[index]["frames"],
            "pick_cost_limit": limit,
            "picked_within": feasible,
            "candidates": [
                {"epoch": c["epoch"], "frames": c["frames"], "reward": r.reward_mean,
                 "cost": r.cost_mean}
                for c, r in zip(candidates, results, strict=True)
            ],
        }
        for entry, report in zip(record["candidates"], reports or [], strict=False):
            entry["report_reward"], entry["report_cost"] = report.reward_mean, report.cost_mean
        return delivered, record, policies[index]

    def _interrupted(self, progress) -> TrainResult:
        self.save()
        progress.write(
            f"Interrupted: checkpoint written to {self.run_dir / 'checkpoints' / 'latest'}; "
            f"continue with resume={self.run_dir}"
        )
        return TrainResult(
            self.run_dir, "interrupted", self.counters, None, self.history, self.stop.exit_status
        )

    # ----------------------------------------------------------------------------- state
    def state_dict(self) -> dict[str, Any]:
        agent = self.agent
        return {
            "config": to_container(self.cfg),
            "counters": dict(vars(self.counters)),
            "loss": agent.loss.state_dict(),
            "optimizers": {name: opt.state_dict() for name, opt in agent.optimizers.items()},
            "lagrangian": agent.lagrangian.state_dict() if agent.lagrangian is not None else None,
            "contrastive": agent.contrastive.state_dict()
            if agent.contrastive is not None
            else None,
            "rng": capture_rng_state(),
            "best_feasible": asdict(self.best),
            "delivery": self.delivery.state_dict() if self.delivery is not None else None,
            "hooks": {name: hook.state_dict() for name, hook in self._hooks.items()},
            # What the next batch and the epoch's row depend on besides the networks: the
            # envs' simulators and generators and the collector's carrier (None where a task
            # cannot be restored exactly), and the epoch's training episodes and last losses.
            "collector": self._collector_state(),
            "test_env": env_snapshot(self.test_env),
            "updates": self.updates.state_dict(),
            "epoch_progress": {
                "train_episodes": [list(e) for e in self._train_episodes],
                "last_losses": {k: v.detach().clone() for k, v in self._last_losses.items()},
                "last_contrastive": dict(self._last_contrastive),
            },
            # The size of every file the run appends to: a resume cuts them back to it.
            "appended_files": self.metrics.appended_files(),
        }

    def _collector_state(self) -> dict[str, Any] | None:
        if self._collector is None:  # resumed, not started yet: the checkpoint's, unchanged
            return self._resume_collector
        snapshot = env_snapshot(self.train_env)
        if snapshot is None:
            return None
        carrier = self._collector.carrier
        return {
            "train_env": snapshot,
            "carrier": {"data": carrier.to_dict(), "batch_size": list(carrier.batch_size)},
        }

    def _save_best(self) -> Path:
        """The policy FSRL would keep (``checkpoints/best``: weights and config, no buffer):
        what ``s3rl-eval checkpoint=<run>/checkpoints/best`` and the final table evaluate."""
        state = self.state_dict()
        return save_checkpoint(
            self.run_dir / "checkpoints" / BEST_CHECKPOINT,
            {key: state[key] for key in ("config", "counters", "loss", "best_feasible")},
        )

    def _save_delivered(self, policy: torch.nn.Module, record: dict[str, Any]) -> Path:
        """The pick as a checkpoint of its own (``checkpoints/delivered``: weights and config,
        no buffer), so that ``s3rl-eval checkpoint=<run>/checkpoints/delivered`` (a video, more
        episodes) evaluates what the run delivered. Its loss holds the pick's actor and the last
        epoch's critics (an evaluation reads only the actor); the run's own networks are left as
        they were."""
        actor = self.agent.actor
        last = {key: value.detach().clone() for key, value in actor.state_dict().items()}
        actor.load_state_dict(policy.state_dict())  # in place: the loss's actor parameters
        try:
            return save_checkpoint(
                self.run_dir / "checkpoints" / DELIVERED_CHECKPOINT,
                {"config": to_container(self.cfg), "counters": dict(vars(self.counters)),
                 "loss": self.agent.loss.state_dict(),
                 "delivered": {k: v for k, v in record.items() if k != "candidates"}},
            )
        finally:
            actor.load_state_dict(last)

    def save(self) -> Path:
        return save_checkpoint(
            self.run_dir / "checkpoints" / "latest",
            self.state_dict(),
            self.replay_buffer,
            self.updates.buffers(),
        )

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """The inverse of :meth:`state_dict`, into a trainer built from the same config:
        networks, optimisers, counters, hooks, the epoch's progress, the envs' snapshots and,
        last, the random streams. The buffers are the checkpoint's files, loaded first (a hook
        may read them): :meth:`Resume.restore <s3rl_torchrl.trainer.resume.Resume.restore>`,
        which also tells whether the run continues exactly."""
        agent = self.agent
        agent.loss.load_state_dict(state["loss"])
        for name, opt in agent.optimizers.items():
            opt.load_state_dict(state["optimizers"][name])
        if agent.lagrangian is not None:
            agent.lagrangian.load_state_dict(state["lagrangian"])
        if agent.contrastive is not None:
            agent.contrastive.load_state_dict(state["contrastive"])
        self.counters = Counters(**state["counters"])
        self.best = BestFeasible(**state.get("best_feasible", {}))
        if self.delivery is not None and state.get("delivery") is not None:
            self.delivery.load_state_dict(state["delivery"])
        self.updates.load_state_dict(state.get("updates") or {})
        hooks = state.get("hooks")
        if hooks is None:  # written before the hooks: the critic diagnostics' episodes had a key
            hooks = {"critic_diagnostics": state.get("recent_episodes")}
        for name, hook in self._hooks.items():
            hook.load_state_dict(hooks.get(name) or {})
        progress = state.get("epoch_progress")
        if progress is not None:
            self._train_episodes = [tuple(e) for e in progress["train_episodes"]]
            self._last_losses = dict(progress["last_losses"])
            self._last_contrastive = dict(progress["last_contrastive"])
        if state.get("test_env") is not None:
            restore_env(self.test_env, state["test_env"])
        # Put into the envs when the collector is built (_start_collector); None: the training
        # episodes restart (Resume.restore says why).
        self._resume_collector = state.get("collector")
        restore_rng_state(state["rng"])


def _take_run_dir(run_dir: Path, new: bool) -> RunLock:
    """Make ``run_dir`` the run's (a ``new`` run's must not hold one) and lock it: no second
    process may train into it until the loop ends (run_lock.py)."""
    # A read-only run directory: one clean line before anything is built or trained.
    check_writable(run_dir)
    check_writable(run_dir / "checkpoints")
    if new:
        # Before anything is built or written, so that run's files stay as they are.
        ensure_new_run_dir(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return RunLock.take(run_dir)


def train(
    cfg: TrainConfig,
    run_dir: str | Path,
    on_epoch_end: Callable[[Trainer, dict[str, Any]], None] | None = None,
    hooks: dict[str, TrainerHook] | None = None,
) -> TrainResult:
    """Train from a validated config into ``run_dir`` (or the run being resumed), with extra
    ``hooks`` (:class:`Trainer`)."""
    return Trainer(cfg, run_dir, on_epoch_end, hooks).run()
