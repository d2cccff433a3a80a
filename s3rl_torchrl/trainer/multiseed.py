"""Several seeds in one process: K independent agents, one batched gradient step per step.

``s3rl-train seeds=[10,20,30,40,50] ...`` (or :func:`train_seeds`) trains one agent per seed.
Each seed is a :class:`SeedRun`: the single-seed :class:`~s3rl_torchrl.trainer.Trainer` with
its own envs, replay buffer and sampler, actor, critics, alpha, Lagrangian controller,
contrastive phase, counters, run directory ``<run dir>/seed<k>/`` and checkpoints, all built
from its own seed exactly as a single-seed run builds them. What the group shares is the
gradient step: :class:`~s3rl_torchrl.algorithms.StackedSACLag` stacks the K losses' tensors
and runs them as one vmapped forward and backward (the gradient step dominates a run's time
and at these sizes it is overhead-bound, docs/benchmarks.md).

Random streams: each seed owns a torch generator state, swapped in around everything of that
seed that draws (collecting, sampling a batch, the loss's normal draws, the contrastive phase,
evaluation), in the single-seed loop's order: seed k draws what the single run with seed k
draws. Read top to bottom, :meth:`MultiSeedTrainer.run` is :meth:`Trainer.run` over K seeds.
"""

from __future__ import annotations

import contextlib
import copy
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from tqdm.auto import tqdm

from s3rl_torchrl.algorithms.stacked import StackedSACLag, draw_noise
from s3rl_torchrl.trainer.checkpoint import GROUP_FILE, check_writable
from s3rl_torchrl.trainer.config import TrainConfig, to_container
from s3rl_torchrl.trainer.loop import StopRequest, Trainer, TrainResult, compile_loss
from s3rl_torchrl.trainer.resume import check_group


def seed_dir(group_dir: str | Path, seed: int) -> Path:
    """Where seed ``seed`` of a group writes its run (config, metrics, checkpoints)."""
    return Path(group_dir) / f"seed{seed}"


class SeedRun(Trainer):
    """One seed of a group: a single-seed Trainer whose gradient steps the group does.

    Its checkpoint has the single-run format (the loss's tensors, its slice of the group's
    optimiser states), so every single-run tool reads it.
    """

    group: StackedSACLag | None = None
    index: int = 0
    restored_optimizers: dict[str, Any] | None = None

    def state_dict(self) -> dict[str, Any]:
        state = super().state_dict()
        # The loss's tensors are views of the group's stacks: torch.save of a view writes the
        # whole stack, so save copies.
        state["loss"] = {key: value.clone() for key, value in state["loss"].items()}
        state["optimizers"] = self.group.optimizer_state(self.index)
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self.restored_optimizers = state["optimizers"]  # stacked by the group once it exists


@dataclass
class MultiSeedResult:
    run_dir: Path
    status: str  # "finished" or "interrupted"
    runs: list[TrainResult] = field(default_factory=list)  # one per seed, in `seeds` order


class MultiSeedTrainer:
    """K :class:`SeedRun` and the :class:`StackedSACLag` that updates them; :meth:`run` is the
    loop. ``on_epoch_end(seed_run, row)`` is called at each seed's epoch end (``seed_run.stop()``
    stops the whole group at the next safe point)."""

    def __init__(
        self,
        cfg: TrainConfig,
        run_dir: str | Path,
        on_epoch_end: Callable[[Trainer, dict[str, Any]], None] | None = None,
    ) -> None:
        if not cfg.seeds:
            raise ValueError("MultiSeedTrainer needs cfg.seeds (a list of seeds)")
        self.cfg = cfg
        self.stop = StopRequest()
        self.run_dir = Path(cfg.resume) if cfg.resume else Path(run_dir)
        self._check_group_dir()
        self.members: list[SeedRun] = []
        self._rng_states: list[torch.Tensor] = []
        for index, seed in enumerate(cfg.seeds):
            member_cfg = copy.deepcopy(cfg)
            member_cfg.seed, member_cfg.seeds = seed, None
            member_cfg.resume = str(seed_dir(self.run_dir, seed)) if cfg.resume else None
            # Builds and seeds everything as a single run with this seed does (seed_everything,
            # then envs, buffer, agent), and restores its checkpoint when resuming.
            member = SeedRun(member_cfg, seed_dir(self.run_dir, seed), on_epoch_end)
            member.index, member.stop = index, self.stop
            self.members.append(member)
            self._rng_states.append(torch.get_rng_state())
        algo = cfg.algo
        self.stacked = StackedSACLag(
            [m.agent.loss for m in self.members],
            algo.actor_lr,
            algo.critic_lr,
            algo.alpha_lr,
            algo.tau,
            compile_fn=compile_loss if cfg.compile else None,
        )
        for member in self.members:
            member.group = self.stacked
        if cfg.resume:
            self.stacked.load_optimizer_states([m.restored_optimizers for m in self.members])
        else:
            (self.run_dir / GROUP_FILE).write_text(json.dumps(to_container(cfg), indent=2))
        self._action_dim = self.members[0].train_env.action_spec.shape[-1]

    def _check_group_dir(self) -> None:
        check_writable(self.run_dir)  # one clean line, before anything is built
        if self.cfg.resume:
            check_group(self.run_dir, self.cfg.seeds)
            return
        if (self.run_dir / GROUP_FILE).exists():
            raise FileExistsError(
                f"{self.run_dir} already holds a multi-seed run ({GROUP_FILE}); continue it "
                f"with resume={self.run_dir} or train into a new directory."
            )
        self.run_dir.mkdir(parents=True, exist_ok=True)

    @contextlib.contextmanager
    def _seed_rng(self, index: int) -> Iterator[None]:
        """Seed ``index``'s torch random stream is the global one inside the block."""
        torch.set_rng_state(self._rng_states[index])
        try:
            yield
        finally:
            self._rng_states[index] = torch.get_rng_state()

    # ----------------------------------------------------------------------------- the loop
    def run(self) -> MultiSeedResult:
        cfg, lead = self.cfg, self.members[0].counters
        self.stop.install()
        progress = tqdm(
            total=cfg.collector.total_frames,
            initial=lead.frames,
            unit="frame",
            desc=f"{len(self.members)} seeds",
            disable=not cfg.logger.progress_bar,
            dynamic_ncols=True,
        )
        collectors = []
        try:
            # Built first, so that a resumed group puts each seed's envs and carrier back before
            # anything else runs (Trainer._start_collector); none when no frame is left.
            for index, member in enumerate(self.members):
                with self._seed_rng(index):
                    collectors.append(member._start_collector())
            # A resumed group first pays what the interrupted one owed for its last batches.
            if not self._finish_batch():
                return self._interrupted(progress)
            if all(collector is not None for collector in collectors):
                iterators = [iter(collector) for collector in collectors]
                while True:
                    batches = []
                    for index, iterator in enumerate(iterators):
                        with self._seed_rng(index):
                            batches.append(next(iterator, None))
                    if batches[0] is None:
                        break
                    for member, batch in zip(self.members, batches, strict=True):
                        frames = batch.numel()
                        member.counters.frames += frames
                        member._store(batch)
                        member._update_lagrangian(batch)
                        member.counters.pending_updates += member._updates_owed(frames)
                    progress.update(batches[0].numel())
                    if not self._finish_batch():
                        return self._interrupted(progress)
            finals = []
            for index, member in enumerate(self.members):
                with self._seed_rng(index):
                    finals.append(member._saved_final_evaluation() or member._final_evaluation())
            runs = [
                TrainResult(m.run_dir, "finished", m.counters, final, m.history)
                for m, final in zip(self.members, finals, strict=True)
            ]
            return MultiSeedResult(self.run_dir, "finished", runs)
        finally:
            for member, collector in zip(self.members, collectors):
                if collector is not None:
                    # A shut-down collector has no carrier: keep what a later save() needs.
                    member._resume_collector = member._collector_state()
                    member._collector = None
                    collector.shutdown()
            progress.close()
            self.stop.uninstall()
            for member in self.members:
                member.run_lock.release()

    def _finish_batch(self) -> bool:
        """The gradient steps owed, then each seed's epoch end. False: stopped."""
        lead = self.members[0].counters
        owed = {m.counters.pending_updates for m in self.members}
        if len(owed) > 1:  # same frames and buffer sizes: cannot differ, but never step apart
            raise RuntimeError(f"the seeds owe different numbers of gradient steps: {owed}")
        while lead.pending_updates >= 1.0:
            if self.stop.requested:
                return False
            self._gradient_step()
        for index, member in enumerate(self.members):
            if member._epochs_due() > member.counters.epochs:
                with self._seed_rng(index):
                    member._end_epoch()
        return not self.stop.requested or lead.frames >= self.cfg.collector.total_frames

    def _gradient_step(self) -> None:
        """Each seed samples its batch and its loss's normal draws from its own stream, then one
        batched update of every seed, then each seed's counters and contrastive phase."""
        batches, noise = [], []
        for index, member in enumerate(self.members):
            with self._seed_rng(index):
                batches.append(member.replay_buffer.sample())
                noise.append(draw_noise(self.cfg.algo.batch_size, self._action_dim))
        losses: TensorDictBase = self.stacked.update(torch.stack(batches), torch.stack(noise))
        for index, member in enumerate(self.members):
            with self._seed_rng(index):
                member._after_gradient_step(losses[index])

    def _interrupted(self, progress) -> MultiSeedResult:
        for index, member in enumerate(self.members):
            with self._seed_rng(index):
                member.save()
        progress.write(
            f"Interrupted: checkpoints written to {self.run_dir}/seed*/checkpoints/latest; "
            f"continue with resume={self.run_dir} 'seeds=[{','.join(map(str, self.cfg.seeds))}]'"
        )
        runs = [
            TrainResult(
                m.run_dir, "interrupted", m.counters, None, m.history, self.stop.exit_status
            )
            for m in self.members
        ]
        return MultiSeedResult(self.run_dir, "interrupted", runs)


def train_seeds(
    cfg: TrainConfig,
    run_dir: str | Path,
    on_epoch_end: Callable[[Trainer, dict[str, Any]], None] | None = None,
) -> MultiSeedResult:
    """Train one agent per seed of ``cfg.seeds`` into ``run_dir/seed<k>/`` (or resume them)."""
    return MultiSeedTrainer(cfg, run_dir, on_epoch_end).run()
