"""When gradient steps happen: each algorithm family declares its update schedule.

A schedule is the rule the loop follows after each collected batch, and the count that rule
gives for a config without collecting (:meth:`UpdateSchedule.planned_gradient_steps`), so a
config that would never take a gradient step is refused before anything is built
(``TrainConfig.check``, trainer/config.py) and the final table can name the steps
taken. Each family (``algorithms/sac.py``, ``ddpg.py``, ``ppo.py``) names its schedule; the
loop (trainer/loop.py) only calls the schedule's methods:

- :class:`OffPolicySchedule` (SAC, DDPG families): every batch goes into one replay buffer; the
  loop owes ``update_per_step`` gradient steps per frame of every batch that ends at or after
  ``init_random_frames`` (FSRL learns only after the uniform-random warm-up) and leaves at least
  ``batch_size`` transitions in the buffer; owed fractions carry over to the next batch.
- :class:`OnPolicySchedule` (PPO family): no warm-up, the policy collects from the first frame;
  after each collect the advantages (GAE) are computed on the whole batch, the batch replaces
  the previous one in a rollout buffer, and ``ppo_epochs`` passes of ``ceil(frames /
  batch_size)`` minibatches (drawn without replacement, the last one shorter) are owed.

The runtime halves (what to store, what to sample) are :class:`ReplayUpdates` and
:class:`RolloutUpdates`, which each schedule builds (:meth:`UpdateSchedule.updates`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, Protocol

from tensordict import TensorDict, TensorDictBase
from torchrl.data import LazyTensorStorage, SamplerWithoutReplacement, TensorDictReplayBuffer
from torchrl.objectives import LossModule

from s3rl_torchrl.transforms.nstep import NStepTransform, make_nstep_transform


# What a schedule reads of a run's config. This module owns these types, so it imports nothing
# of the configs (trainer/config.py's CollectorConfig and the families' configs satisfy them).
class CollectorSettings(Protocol):
    num_envs: int
    frames_per_batch: int
    total_frames: int
    init_random_frames: int


class OffPolicySettings(Protocol):
    batch_size: int
    buffer_size: int
    gamma: float
    n_step: int
    update_per_step: float


class OnPolicySettings(Protocol):
    batch_size: int
    ppo_epochs: int


def collector_batch_frames(collector: CollectorSettings) -> int:
    """Frames per collected batch: torchrl's collector rounds up to whole steps of every env."""
    return math.ceil(collector.frames_per_batch / collector.num_envs) * collector.num_envs


def collected_batches(collector: CollectorSettings) -> int:
    """Batches a run collects: the last one may run past ``total_frames`` (whole batches)."""
    return math.ceil(collector.total_frames / collector_batch_frames(collector))


class UpdateSchedule:
    """What an algorithm family declares: its warm-up and the gradient steps each batch owes.

    Subclasses define :meth:`warmup_frames` and :meth:`steps_owed`; the plan replays the latter
    batch by batch.
    """

    name: ClassVar[str]

    def __init__(self, collector: CollectorSettings, algo: Any) -> None:
        # algo: the family's config (OffPolicySettings, OnPolicySettings)
        self.collector, self.algo = collector, algo

    def warmup_frames(self) -> int:
        """Frames the collector draws uniformly at random before the policy acts."""
        raise NotImplementedError

    def steps_owed(self, frames: int, batch_frames: int, stored: int) -> float:
        """Gradient steps owed for a batch of ``batch_frames`` frames that brought the run to
        ``frames`` frames and left ``stored`` transitions in the buffer the updates sample."""
        raise NotImplementedError

    def stored_after(self, batches: int) -> int:
        """Length of the buffer the updates sample after ``batches`` batches."""
        raise NotImplementedError

    def planned_gradient_steps(self, stop_at: int | None = None) -> int:
        """The number of gradient steps a run of this config takes; with ``stop_at``,
        counting stops once that many are reached."""
        batch_frames = collector_batch_frames(self.collector)
        pending, steps = 0.0, 0
        for k in range(1, collected_batches(self.collector) + 1):
            pending += self.steps_owed(k * batch_frames, batch_frames, self.stored_after(k))
            # The loop subtracts 1.0 per step; below 2**53 that is exact, so floor gives the same.
            whole = math.floor(pending)
            steps += whole
            pending -= whole
            if stop_at is not None and steps >= stop_at:
                break
        return steps

    def no_learning_reason(self, prefix: str) -> str:
        """Why a config takes no gradient step (for the config error), without the fixes."""
        raise NotImplementedError

    def updates(
        self,
        loss: LossModule,
        labelled: TensorDictReplayBuffer,
        labelled_keys: list,
        keep_at_t: tuple[str, ...],
        prepare: Callable[[TensorDictBase], TensorDictBase] | None = None,
    ) -> ReplayUpdates | RolloutUpdates:
        """The run-time half: what each collected batch is stored in, what each gradient step
        samples. ``labelled`` is the trainer's buffer of labelled states (off-policy: the replay
        buffer itself), which keeps ``labelled_keys`` of every step (the sampler's label, the
        policy encoder's inputs, what hooks store); ``keep_at_t`` are the ``next`` entries that
        describe step ``t`` itself (labels: n-step returns leave them there); ``prepare``
        (on-policy) computes what the gradient steps read from a whole batch.

        The buffers keep what is read back from them, nothing else: a sample gathers every
        stored entry, and the collector and transforms write ~27 (episode sums, counters, the
        policy's outputs, ...), which made drawing a batch cost 0.86 ms instead of 0.58.
        """
        raise NotImplementedError


class OffPolicySchedule(UpdateSchedule):
    """Replay buffer, uniform-random warm-up, ``update_per_step`` gradient steps per frame."""

    name = "off_policy"

    def warmup_frames(self) -> int:
        return self.collector.init_random_frames

    def steps_owed(self, frames: int, batch_frames: int, stored: int) -> float:
        if frames < self.collector.init_random_frames:
            return 0.0
        if stored < self.algo.batch_size:
            return 0.0
        return self.algo.update_per_step * batch_frames

    def stored_after(self, batches: int) -> int:
        """Replay-buffer length after ``batches`` batches: with n-step returns (``n_step > 1``)
        the n-step transform holds back the last ``n_step`` frames of every env copy until the
        next batch (torchrl's ``MultiStepTransform`` buffering); the buffer keeps
        ``buffer_size`` at most."""
        collector, algo = self.collector, self.algo
        steps_per_env = batches * collector_batch_frames(collector) // collector.num_envs
        held_back = algo.n_step if algo.n_step > 1 else 0
        return min(algo.buffer_size, collector.num_envs * max(0, steps_per_env - held_back))

    def no_learning_reason(self, prefix: str) -> str:
        return (
            "no gradient step would happen: learning starts with the first batch "
            f"({collector_batch_frames(self.collector)} frames) that ends at or after "
            f"{prefix}collector.init_random_frames ({self.collector.init_random_frames}) and "
            f"leaves at least {prefix}algo.batch_size ({self.algo.batch_size}) transitions in "
            f"the replay buffer, then takes {prefix}algo.update_per_step "
            f"({self.algo.update_per_step}) steps per frame"
        )

    def updates(self, loss, labelled, labelled_keys, keep_at_t, prepare=None) -> ReplayUpdates:
        # n-step windows need consecutive batches of the same env copies: the transform keeps
        # the last n frames of each copy until the next batch (paper: n = 2).
        algo = self.algo
        nstep = (
            make_nstep_transform(algo.n_step, algo.gamma, keep_keys=keep_at_t)
            if algo.n_step > 1
            else None
        )
        # The losses' inputs (n-step reward and discount exponent included), the labelled keys.
        steps = loss.value_estimator.tensor_keys.steps_to_next_obs
        keys = [*loss.in_keys, steps, *labelled_keys]
        return ReplayUpdates(self, labelled, list(dict.fromkeys(keys)), nstep)


class OnPolicySchedule(UpdateSchedule):
    """Collect, GAE on the batch, ``ppo_epochs`` passes of minibatches over it; no warm-up.

    ``collector.init_random_frames`` and ``algo.update_per_step`` are not used: each batch is
    learnt from by the policy that collected it, then dropped (``algo.buffer_size`` sizes the
    FIFO of labelled states the contrastive phase and the probe sample, not a replay buffer).
    """

    name = "on_policy"

    def warmup_frames(self) -> int:
        return 0

    def minibatches_per_epoch(self, batch_frames: int) -> int:
        """``ceil(frames / batch_size)``: torchrl's ``SamplerWithoutReplacement`` keeps the
        shorter last minibatch (``drop_last=False``)."""
        return math.ceil(batch_frames / self.algo.batch_size)

    def steps_owed(self, frames: int, batch_frames: int, stored: int) -> float:
        return float(self.algo.ppo_epochs * self.minibatches_per_epoch(stored))

    def stored_after(self, batches: int) -> int:
        return collector_batch_frames(self.collector) if batches > 0 else 0

    def no_learning_reason(self, prefix: str) -> str:  # every batch owes >= ppo_epochs steps
        return "no gradient step would happen"

    def updates(self, loss, labelled, labelled_keys, keep_at_t, prepare=None) -> RolloutUpdates:
        if prepare is None:
            raise ValueError("the on-policy schedule needs `prepare` (the batch's advantages)")
        # One collect's transitions; each PPO epoch a new permutation of ceil(frames /
        # batch_size) minibatches (the last one shorter).
        rollout = TensorDictReplayBuffer(
            storage=LazyTensorStorage(collector_batch_frames(self.collector)),
            sampler=SamplerWithoutReplacement(drop_last=False),
            batch_size=self.algo.batch_size,
        )
        keys = list(loss.in_keys)
        advantage_keys = ("advantage", "value_target", "cost_advantage", "cost_value_target")
        keys += [
            getattr(loss.tensor_keys, k) for k in advantage_keys if hasattr(loss.tensor_keys, k)
        ]
        return RolloutUpdates(
            self, rollout, prepare, list(dict.fromkeys(keys)), labelled, labelled_keys
        )


# ------------------------------------------------------------------------------- runtime
class ReplayUpdates:
    """Off-policy at run time: store each batch (n-step transitions) in the replay buffer, draw
    each gradient step's batch from it. The same buffer feeds the contrastive phase."""

    def __init__(
        self,
        schedule: OffPolicySchedule,
        replay_buffer: TensorDictReplayBuffer,
        stored_keys: list,
        nstep: NStepTransform | None = None,
    ) -> None:
        self.schedule, self.replay_buffer = schedule, replay_buffer
        self.stored_keys, self.nstep = stored_keys, nstep

    def store(self, batch: TensorDictBase) -> None:
        data = self.nstep.inv(batch) if self.nstep is not None else batch
        if data is not None and data.numel():
            # Not strict: without n-step returns (n_step=1) there is no `steps_to_next_obs`.
            self.replay_buffer.extend(data.select(*self.stored_keys, strict=False).reshape(-1))

    def owed(self, frames: int, batch_frames: int) -> float:
        return self.schedule.steps_owed(frames, batch_frames, len(self.replay_buffer))

    def sample(self) -> TensorDictBase:
        return self.replay_buffer.sample()

    def buffers(self) -> dict[str, TensorDictReplayBuffer]:
        """Extra buffers a checkpoint keeps besides ``replay_buffer`` (none)."""
        return {}

    def load(self, checkpoint_dir: Path) -> None:
        pass

    def state_dict(self) -> dict[str, Any]:
        """The n-step transform's held-back frames (the start of the next batch's windows)."""
        held = None if self.nstep is None else self.nstep.held_frames
        if held is None:
            return {"nstep_held": None}
        return {"nstep_held": held.to_dict(), "nstep_held_shape": list(held.batch_size)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if self.nstep is None or state.get("nstep_held") is None:
            return
        held = TensorDict(state["nstep_held"], batch_size=state["nstep_held_shape"])
        self.nstep.load_held_frames(held)

    def end_episodes(self) -> None:
        """The envs restart their episodes before the next batch: the n-step windows held back
        for it end where those episodes were cut (:meth:`NStepTransform.end_held_episodes`)."""
        if self.nstep is not None:
            self.nstep.end_held_episodes()


class RolloutUpdates:
    """On-policy at run time: each batch gets its advantages (``prepare``: GAE of the reward,
    and of the cost for PPO-Lag) with the critics of the policy that collected it, then
    replaces the previous batch in ``rollout`` (torchrl's ``SamplerWithoutReplacement``: each
    pass over the batch is a new permutation). ``labelled`` (the trainer's ``replay_buffer``,
    a FIFO of recent labelled states) gets the keys in ``labelled_keys`` of every batch: the
    contrastive phase and the linear probe sample it (docs/representation.md)."""

    ROLLOUT_DIR = "rollout_buffer"

    def __init__(
        self,
        schedule: OnPolicySchedule,
        rollout: TensorDictReplayBuffer,
        prepare: Callable[[TensorDictBase], TensorDictBase],
        rollout_keys: list,
        labelled: TensorDictReplayBuffer,
        labelled_keys: list,
    ) -> None:
        self.schedule, self.rollout, self.prepare = schedule, rollout, prepare
        self.rollout_keys, self.labelled, self.labelled_keys = rollout_keys, labelled, labelled_keys

    def store(self, batch: TensorDictBase) -> None:
        self.labelled.extend(batch.select(*self.labelled_keys).reshape(-1))
        batch = self.prepare(batch)  # [envs, time]: GAE runs along the last dimension
        self.rollout.empty()
        self.rollout.extend(batch.select(*self.rollout_keys, strict=False).reshape(-1))

    def owed(self, frames: int, batch_frames: int) -> float:
        return self.schedule.steps_owed(frames, batch_frames, len(self.rollout))

    def sample(self) -> TensorDictBase:
        return self.rollout.sample()

    def buffers(self) -> dict[str, TensorDictReplayBuffer]:
        """The rollout (its sampler's permutation included): a run stopped between two
        minibatches resumes on the same batch and the same remaining minibatches."""
        return {self.ROLLOUT_DIR: self.rollout}

    def load(self, checkpoint_dir: Path) -> None:
        self.rollout.loads(Path(checkpoint_dir) / self.ROLLOUT_DIR)

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        pass

    def end_episodes(self) -> None:
        """Nothing carries over: each batch's advantages are computed within the batch."""
