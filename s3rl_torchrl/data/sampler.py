"""``SafeUnsafeSampler``: a replay-buffer sampler stratified by the safety label.

The buffer is partitioned into safe and unsafe slots (paper, eqs. 10-11). The partition is kept
up to date as the buffer writes, so drawing a batch never scans the storage:

* each stratum is a dense array of storage indices (``members``) plus, per storage slot, its
  position in that array; moving a slot between strata is a swap-with-last removal and an
  append, vectorised over all slots written by one ``extend``;
* the labels are read, on every write, only at the indices just written. The hook is torchrl's
  ``Sampler.mark_update``, which the writer calls through every replay buffer attached to the
  storage after the data is in place, so overwrites in the ring buffer move slots between
  strata and several buffers can share one storage.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch
from tensordict.utils import NestedKey
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.data.replay_buffers.storages import Storage, TensorStorage
from torchrl.data.replay_buffers.writers import ImmutableDatasetWriter

__all__ = [
    "SafeUnsafeSampler",
    "StratumTooSmallError",
    "LabelBinTooSmallError",
    "CONTRASTIVE_ROLE_KEY",
]

CONTRASTIVE_ROLE_KEY = "contrastive_role"
ANCHOR, POSITIVE, NEGATIVE = 0, 1, 2
UNSAFE, SAFE = 0, 1
_EMPTY_SLOT = -1
_STRATUM_NAMES = {SAFE: "safe", UNSAFE: "unsafe"}
# How a collector's [num_envs, time] batch goes into a 1-D buffer (the errors below say it).
_STORE_FLAT = (
    "With an n-step transform in the buffer (make_nstep_transform), extend with the "
    "collector's unflattened [num_envs, time] batch, `rb.extend(data)`: the transform builds "
    "each env's windows along time, then flattens (a flattened batch would join different "
    "envs' steps into one window). Without one, flatten it first: "
    "`rb.extend(data.reshape(-1))`."
)


class StratumTooSmallError(RuntimeError):
    """Raised when a stratum holds too few transitions for the requested batch.

    Attributes:
        num_safe, num_unsafe: the stratum sizes when the batch was requested.
        required_safe, required_unsafe: what the batch needs.
    """

    def __init__(self, num_safe: int, num_unsafe: int, required_safe: int, required_unsafe: int):
        self.num_safe = num_safe
        self.num_unsafe = num_unsafe
        self.required_safe = required_safe
        self.required_unsafe = required_unsafe
        super().__init__(
            f"not enough transitions for this batch: it needs {required_safe} safe and "
            f"{required_unsafe} unsafe, the buffer holds {num_safe} safe and {num_unsafe} unsafe. "
            "Check `replay_buffer.can_sample()` first and skip the update when it is False "
            "(paper, Algorithm 2)."
        )


class LabelBinTooSmallError(StratumTooSmallError):
    """The graded form: no label bin holds ``2B`` transitions while the others hold ``B``.

    Attributes:
        stratum_sizes: transitions per label bin when the batch was requested.
        num_triplets: ``B``.
    """

    def __init__(self, stratum_sizes: list[int], num_triplets: int):
        self.stratum_sizes = list(stratum_sizes)
        self.num_triplets = int(num_triplets)
        RuntimeError.__init__(
            self,
            f"not enough transitions for this batch: a graded contrastive batch needs one label "
            f"bin with {2 * num_triplets} transitions and {num_triplets} in the other bins; the "
            f"bins hold {self.stratum_sizes}. Check `replay_buffer.can_sample()` first and skip "
            "the update when it is False.",
        )


class _SafetyPartition:
    """Partition of the slots of a 1-D storage into strata, updated per write in O(written).

    Two strata (UNSAFE = 0, SAFE = 1) for the binary label; ``num_strata`` label bins for a
    graded one (stratum ``k`` = bin ``k``, see ``SafeUnsafeSampler(bin_edges=...)``).
    """

    def __init__(self, capacity: int, num_strata: int = 2):
        self.capacity = int(capacity)
        self.num_strata = int(num_strata)
        if not 2 <= self.num_strata <= 127:  # int8 slot labels, -1 for an empty slot
            raise ValueError(f"a partition needs 2 to 127 strata, got {self.num_strata}.")
        # Stratum of each slot, or _EMPTY_SLOT (never written since the last empty).
        self.label = torch.full((self.capacity,), _EMPTY_SLOT, dtype=torch.int8)
        # Position of a slot inside its stratum's member array (meaningless for empty slots).
        self.position = torch.zeros(self.capacity, dtype=torch.long)
        self.members = {
            stratum: torch.zeros(self.capacity, dtype=torch.long)
            for stratum in range(self.num_strata)
        }
        self.size = dict.fromkeys(range(self.num_strata), 0)

    def __len__(self) -> int:
        return sum(self.size.values())

    def empty(self) -> None:
        self.label.fill_(_EMPTY_SLOT)
        self.size = dict.fromkeys(range(self.num_strata), 0)

    def update(self, index: torch.Tensor, stratum: torch.Tensor) -> None:
        """Set the stratum of the slots ``index`` (unique, 1-D): the boolean ``safe`` label
        (``True`` -> SAFE) or the integer bin of a graded label."""
        new = stratum.to(torch.int8)
        old = self.label[index]
        changed = old != new
        if not bool(changed.any()):
            return
        index, old, new = index[changed], old[changed], new[changed]
        for stratum in range(self.num_strata):
            leaving = index[old == stratum]
            if leaving.numel():
                self._remove(stratum, leaving)
        self.label[index] = new
        for stratum in range(self.num_strata):
            joining = index[new == stratum]
            if joining.numel():
                self._append(stratum, joining)

    def _remove(self, stratum: int, leaving: torch.Tensor) -> None:
        members, size = self.members[stratum], self.size[stratum]
        new_size = size - leaving.numel()
        positions = self.position[leaving]
        # Marking the leavers lets the tail be filtered without a scratch mask; update() writes
        # their new label right after.
        self.label[leaving] = _EMPTY_SLOT
        tail = members[new_size:size]
        survivors = tail[self.label[tail] == stratum]
        holes = positions[positions < new_size]
        members[holes] = survivors
        self.position[survivors] = holes
        self.size[stratum] = new_size

    def _append(self, stratum: int, joining: torch.Tensor) -> None:
        size = self.size[stratum]
        end = size + joining.numel()
        self.members[stratum][size:end] = joining
        self.position[joining] = torch.arange(size, end, dtype=torch.long)
        self.size[stratum] = end

    def draw(self, stratum: int, count: int, generator, *, distinct: bool) -> torch.Tensor:
        """``count`` storage indices drawn uniformly from one stratum."""
        size = self.size[stratum]
        if count == 0:
            return torch.empty(0, dtype=torch.long)
        if distinct:
            positions = _distinct_uniform(size, count, generator)
        else:
            positions = torch.randint(size, (count,), generator=generator)
        return self.members[stratum][positions]

    def state_dict(self) -> dict[str, Any]:
        state = {
            "capacity": self.capacity,
            "label": self.label.clone(),
            "position": self.position.clone(),
        }
        if self.num_strata == 2:  # the binary partition's format (checkpoints before bins)
            state["safe_members"] = self.members[SAFE][: self.size[SAFE]].clone()
            state["unsafe_members"] = self.members[UNSAFE][: self.size[UNSAFE]].clone()
        else:
            state["strata_members"] = [
                self.members[k][: self.size[k]].clone() for k in range(self.num_strata)
            ]
        return state

    @classmethod
    def from_state_dict(cls, state: dict[str, Any]) -> _SafetyPartition:
        if "strata_members" in state:
            strata = dict(enumerate(state["strata_members"]))
        else:
            strata = {SAFE: state["safe_members"], UNSAFE: state["unsafe_members"]}
        partition = cls(state["capacity"], num_strata=len(strata))
        partition.label.copy_(state["label"])
        partition.position.copy_(state["position"])
        for stratum, members in strata.items():
            partition.members[stratum][: members.numel()] = members
            partition.size[stratum] = members.numel()
        return partition


def _distinct_uniform(n: int, k: int, generator) -> torch.Tensor:
    """``k`` distinct integers in ``[0, n)``, a uniformly random ordered sample, in O(k) time.

    For ``k <= n / 4``: draw a few more than ``k`` with replacement, keep the distinct values and
    draw again if fewer than ``k`` remain. Every step treats the values of ``[0, n)`` alike, so
    the set obtained is a uniformly random subset of its size; a uniformly random ``k`` of them,
    in random order, is then a uniform ordered sample without replacement, and any fixed split
    of it (anchors | positives) pairs slots at random. A full ``randperm(n)`` would cost O(n).
    """
    if k > n:
        raise ValueError(f"cannot draw {k} distinct indices out of {n}")
    if 4 * k >= n:
        return torch.randperm(n, generator=generator)[:k]
    # About k^2 / 2n draws repeat; twice that plus a margin makes one round enough nearly always.
    draws = k + 2 * k * k // n + 8
    chosen = torch.unique(torch.randint(n, (draws,), generator=generator))
    while chosen.numel() < k:
        extra = torch.randint(n, (draws - chosen.numel(),), generator=generator)
        chosen = torch.unique(torch.cat([chosen, extra]))
    return chosen[torch.randperm(chosen.numel(), generator=generator)[:k]]


class SafeUnsafeSampler(Sampler):
    """Replay-buffer sampler stratified by a boolean safety label (``True`` = safe).

    Use it as the sampler of a :class:`~torchrl.data.TensorDictReplayBuffer` over a 1-D
    :class:`~torchrl.data.LazyTensorStorage` or :class:`~torchrl.data.LazyMemmapStorage`.
    It keeps the safe/unsafe partition of the stored slots up to date on every write (reading the
    label only at the written indices), so sampling is O(batch) whatever the buffer size.

    Each slot holds one transition. A collector's ``[num_envs, time]`` batch goes in
    unflattened when the buffer has an n-step transform
    (:func:`~s3rl_torchrl.transforms.make_nstep_transform`, which builds each env's windows
    along time and then flattens), and flattened (``data.reshape(-1)``) when it has none.

    Modes:

    * **uniform** (default, ``unsafe_fraction=None``, ``contrastive=False``): uniform with
      replacement over the whole buffer, like :class:`~torchrl.data.RandomSampler`. The partition
      is still maintained, so contrastive views of the same buffer can use it (see
      :meth:`contrastive_view`).
    * **stratified** (``unsafe_fraction=f``): ``round(f * batch_size)`` transitions drawn
      uniformly with replacement from the unsafe stratum, the rest from the safe stratum, then
      shuffled. Useful to oversample rare violations; the batch is biased on purpose.
    * **contrastive** (``contrastive=True``, paper Algorithm 2): ``batch_size`` must be ``3 * B``;
      a batch is ``B`` anchors and ``B`` positives from the safe stratum and ``B`` negatives from
      the unsafe stratum, in that order, with ``"contrastive_role"`` = 0 / 1 / 2 (anchor /
      positive / negative). The ``2B`` safe indices are distinct (anchors and positives disjoint)
      and so are the ``B`` unsafe ones; anchor ``i`` is paired with positive ``i``.

    When a stratum is too small (contrastive: fewer than ``2B`` safe or ``B`` unsafe; stratified:
    an empty stratum the batch needs) :meth:`sample` raises :class:`StratumTooSmallError` and
    :meth:`can_sample` (so ``replay_buffer.can_sample()``) returns ``False``: check it first.

    Draws use the generator the replay buffer hands to its sampler (``generator=`` of the
    buffer), or torch's global RNG when it has none, so a seeded run is reproducible.

    **Graded labels** (``bin_edges=[e_1, ..., e_{K-1}]``, increasing): ``label_key`` holds a
    float label (e.g. ``("next", "cost_to_go")`` of :class:`~s3rl_torchrl.transforms.CostToGo`)
    and the partition has ``K`` strata, the label bins ``[-inf, e_1), [e_1, e_2), ...,
    [e_{K-1}, inf)``, kept up to date the same way. The contrastive mode then draws by label
    distance: one anchor bin per batch, uniformly among the bins that hold ``2B`` transitions
    while the other bins hold ``B``; ``B`` anchors and ``B`` positives from that bin (distinct),
    and ``B`` distinct negatives from the other bins, split as evenly as their sizes allow (so
    rare far bins are represented, as Algorithm 2 represents the rare unsafe states). The
    uniform mode is unchanged; ``unsafe_fraction`` has no graded form.

    Args:
        label_key: the label entry read from the stored data. Defaults to
            ``("next", "safe")`` (written by :class:`~s3rl_torchrl.transforms.CostLabel`).

    Keyword Args:
        unsafe_fraction (float, optional): fraction of unsafe transitions per batch, in [0, 1].
        contrastive (bool): contrastive triplet batches. Exclusive with ``unsafe_fraction``.
        bin_edges (sequence of float, optional): the inner edges of the graded label's bins
            (at least one, strictly increasing, at most 126); ``None`` (default): the binary
            label.

    .. note:: Only writes made through a replay buffer's writer (``extend`` / ``add``) are seen.
       After ``rb[idx] = data`` call ``rb.mark_update(idx)``. If the storage was filled some
       other way, call :meth:`rebuild` once (a full scan); :meth:`sample` raises if the
       partition does not account for every stored transition.

    Examples:
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100_000),
        ...                             sampler=SafeUnsafeSampler(), batch_size=256)
        >>> contrastive = SafeUnsafeSampler.contrastive_view(rb, num_triplets=256)
        >>> rb.extend(data)                      # one write; both see it
        >>> batch = rb.sample()                  # 256 uniform transitions for SAC
        >>> if contrastive.can_sample():
        ...     triplets = contrastive.sample()  # 768 = 256 anchors | positives | negatives
    """

    def __init__(
        self,
        label_key: NestedKey = ("next", "safe"),
        *,
        unsafe_fraction: float | None = None,
        contrastive: bool = False,
        bin_edges: Sequence[float] | None = None,
    ):
        if bin_edges is not None:
            bin_edges = tuple(float(e) for e in bin_edges)
            ordered = all(a < b for a, b in zip(bin_edges, bin_edges[1:]))
            if not bin_edges or len(bin_edges) > 126 or not ordered or not all(
                math.isfinite(e) for e in bin_edges
            ):
                raise ValueError(
                    "SafeUnsafeSampler: bin_edges must be 1 to 126 finite, strictly increasing "
                    f"numbers, got {list(bin_edges)}."
                )
            if unsafe_fraction is not None:
                raise ValueError(
                    "SafeUnsafeSampler: unsafe_fraction has no graded form; with bin_edges use "
                    "the uniform or the contrastive mode."
                )
        if unsafe_fraction is not None:
            if contrastive:
                raise ValueError(
                    "SafeUnsafeSampler: contrastive=True fixes the batch composition "
                    "(B safe anchors, B safe positives, B unsafe negatives); "
                    "do not pass unsafe_fraction with it."
                )
            unsafe_fraction = float(unsafe_fraction)
            if not 0.0 <= unsafe_fraction <= 1.0:
                raise ValueError(
                    f"SafeUnsafeSampler: unsafe_fraction must be in [0, 1] or None (uniform), "
                    f"got {unsafe_fraction}."
                )
        self.label_key = label_key
        self.bin_edges = bin_edges
        self.unsafe_fraction = unsafe_fraction
        self.contrastive = bool(contrastive)
        self._partition: _SafetyPartition | None = None
        # A view sampler reads (never writes) the partition of the sampler it was made from.
        self._owner: SafeUnsafeSampler | None = None

    # ------------------------------------------------------------------ partition upkeep
    @property
    def partition(self) -> _SafetyPartition | None:
        return self._owner.partition if self._owner is not None else self._partition

    @property
    def graded(self) -> bool:
        """Whether the strata are bins of a graded label (``bin_edges``)."""
        return self.bin_edges is not None

    @property
    def num_strata(self) -> int:
        return 2 if self.bin_edges is None else len(self.bin_edges) + 1

    @property
    def stratum_sizes(self) -> list[int]:
        """Transitions per stratum: ``[unsafe, safe]``, or per label bin (graded)."""
        partition = self.partition
        if partition is None:
            return [0] * self.num_strata
        return [partition.size[k] for k in range(self.num_strata)]

    def stratum_of(self, label: torch.Tensor) -> torch.Tensor:
        """The stratum of each label: ``safe`` as 0/1, or the bin index of a graded label."""
        if self.bin_edges is None:
            return label.to(torch.int8)
        edges = torch.tensor(self.bin_edges, dtype=label.dtype, device=label.device)
        # right=True: bin k is [e_k, e_{k+1}), an edge value opens the bin above it.
        return torch.bucketize(label, edges, right=True).to(torch.int8)

    @property
    def num_safe(self) -> int:
        """Number of stored transitions labelled safe (binary label; stratum 1 when graded)."""
        partition = self.partition
        return 0 if partition is None else partition.size[SAFE]

    @property
    def num_unsafe(self) -> int:
        """Number of stored transitions labelled unsafe."""
        partition = self.partition
        return 0 if partition is None else partition.size[UNSAFE]

    def mark_update(self, index: int | torch.Tensor, *, storage: Storage | None = None) -> None:
        if self._owner is not None:
            return
        if storage is None:
            raise RuntimeError(
                "SafeUnsafeSampler.mark_update needs the storage to read the labels of the "
                "written slots; write through the replay buffer (extend / add)."
            )
        index = torch.as_tensor(index).reshape(-1).to("cpu", torch.long)
        if index.numel() == 0:
            return
        # A write larger than the ring wraps onto the same slot twice; the storage keeps one.
        index = torch.unique(index)
        self._ensure_partition(storage)
        self._partition.update(index, self.stratum_of(self._read_labels(storage, index)))

    def extend(self, index: torch.Tensor) -> None:
        # The partition is updated in mark_update, which also fires for writes made through
        # another buffer sharing the storage and receives the storage to read labels from.
        return

    def add(self, index: int) -> None:
        return

    def rebuild(self, storage: Storage) -> None:
        """Recompute the partition from every stored transition (one full scan).

        Only needed when the storage was filled without going through a replay buffer that
        uses this sampler (e.g. a storage loaded by hand).
        """
        if self._owner is not None:
            self._owner.rebuild(storage)
            return
        self._check_storage(storage)
        self._partition = _SafetyPartition(storage.max_size, self.num_strata)
        if len(storage):
            index = torch.arange(len(storage))
            self._partition.update(index, self.stratum_of(self._read_labels(storage, index)))

    def _check_storage(self, storage: Storage) -> None:
        if not isinstance(storage, TensorStorage):
            raise TypeError(
                f"SafeUnsafeSampler works with LazyTensorStorage or LazyMemmapStorage "
                f"(a TensorStorage), got {type(storage).__name__}."
            )
        if storage.ndim != 1:
            raise ValueError(
                f"SafeUnsafeSampler needs a 1-D storage, one transition per slot (got "
                f"ndim={storage.ndim}): build it with the default ndim=1. {_STORE_FLAT}"
            )

    def _ensure_partition(self, storage: Storage) -> None:
        if self._partition is None:
            self._check_storage(storage)
            self._partition = _SafetyPartition(storage.max_size, self.num_strata)
        elif self._partition.capacity != storage.max_size:
            raise RuntimeError(
                f"SafeUnsafeSampler: the partition was built for a storage of "
                f"{self._partition.capacity} slots but this storage has {storage.max_size}; "
                "use one sampler per storage."
            )

    def _read_labels(self, storage: TensorStorage, index: torch.Tensor) -> torch.Tensor:
        stored = storage._storage
        try:
            label = stored.get(self.label_key)
        except KeyError:
            label = None
        if label is None:
            keys = sorted(str(k) for k in stored.keys(True, True))
            raise KeyError(
                f"SafeUnsafeSampler: the stored data has no label entry {self.label_key!r}; "
                f"stored keys are {keys}. Label the transitions with "
                "s3rl_torchrl.transforms.CostLabel (it writes ('next', 'safe')) or pass "
                "label_key= to the sampler."
            )
        if self.graded:
            if not label.is_floating_point():
                raise TypeError(
                    f"SafeUnsafeSampler(bin_edges=...): the graded label {self.label_key!r} "
                    f"must be a float tensor, got dtype {label.dtype}."
                )
        elif label.dtype != torch.bool:
            raise TypeError(
                f"SafeUnsafeSampler: the label {self.label_key!r} must be a bool tensor "
                f"(True = safe), got dtype {label.dtype}. CostLabel writes ('next', 'safe') "
                "from ('next', 'cost')."
            )
        label = label[index.to(label.device)].reshape(index.numel(), -1)
        if label.shape[-1] != 1:
            raise ValueError(
                f"SafeUnsafeSampler: each storage slot must hold one transition with one label, "
                f"but a slot's {self.label_key!r} has {label.shape[-1]} entries (stored shape "
                f"{tuple(stored.get(self.label_key).shape)}). {_STORE_FLAT}"
            )
        label = label[:, 0].cpu()
        if self.graded and bool(torch.isnan(label).any()):
            raise ValueError(
                f"SafeUnsafeSampler: NaN graded labels {self.label_key!r} at storage slots "
                f"{index[torch.isnan(label)][:5].tolist()}: a row without a label (e.g. a reset "
                "row's margin) was stored."
            )
        return label

    # ------------------------------------------------------------------ sampling
    def _generator(self):
        return self._owner._rng if self._owner is not None else self._rng

    def _requirements(self, batch_size: int) -> tuple[int, int]:
        """(safe, unsafe) transitions needed for one batch in a stratified mode."""
        if self.contrastive:
            if batch_size <= 0 or batch_size % 3:
                raise ValueError(
                    f"SafeUnsafeSampler(contrastive=True): the batch size must be 3 * B "
                    f"(B anchors, B positives, B negatives) with B >= 1, got {batch_size}."
                )
            num_triplets = batch_size // 3
            return 2 * num_triplets, num_triplets
        num_unsafe = round(self.unsafe_fraction * batch_size)
        return batch_size - num_unsafe, num_unsafe

    def _anchor_strata(self, num_triplets: int) -> list[int]:
        """Graded contrastive: the bins that can give ``2B`` anchors and positives while the
        other bins hold ``B`` negatives."""
        sizes = self.stratum_sizes
        total = sum(sizes)
        return [
            k
            for k, size in enumerate(sizes)
            if size >= 2 * num_triplets and total - size >= num_triplets
        ]

    def _is_sampleable(self, required_safe: int, required_unsafe: int) -> bool:
        if self.contrastive and self.graded:
            return bool(self._anchor_strata(required_unsafe))
        if self.contrastive:
            return self.num_safe >= required_safe and self.num_unsafe >= required_unsafe
        return (required_safe == 0 or self.num_safe > 0) and (
            required_unsafe == 0 or self.num_unsafe > 0
        )

    def can_sample(self, storage: Storage, batch_size: int) -> bool:
        if len(storage) == 0:
            return False
        if not self.contrastive and self.unsafe_fraction is None:
            return True
        return self._is_sampleable(*self._requirements(batch_size))

    def sample(self, storage: Storage, batch_size: int) -> tuple[torch.Tensor, dict]:
        if len(storage) == 0:
            raise RuntimeError("SafeUnsafeSampler: cannot sample from an empty storage.")
        generator = self._generator()
        if not self.contrastive and self.unsafe_fraction is None:
            return torch.randint(len(storage), (batch_size,), generator=generator), {}

        partition = self.partition
        if partition is None or len(partition) != len(storage):
            raise RuntimeError(
                f"SafeUnsafeSampler: the partition accounts for "
                f"{0 if partition is None else len(partition)} transitions but the storage "
                f"holds {len(storage)}: data reached the storage without a replay-buffer write "
                "this sampler saw. Call `sampler.rebuild(storage)` once."
            )
        required_safe, required_unsafe = self._requirements(batch_size)
        if not self._is_sampleable(required_safe, required_unsafe):
            if self.graded:
                raise LabelBinTooSmallError(self.stratum_sizes, required_unsafe)
            raise StratumTooSmallError(
                self.num_safe, self.num_unsafe, required_safe, required_unsafe
            )
        if self.contrastive and self.graded:
            return self._sample_graded(partition, batch_size // 3, generator)
        if self.contrastive:
            num_triplets = batch_size // 3
            safe = partition.draw(SAFE, 2 * num_triplets, generator, distinct=True)
            unsafe = partition.draw(UNSAFE, num_triplets, generator, distinct=True)
            role = torch.arange(3, dtype=torch.long).repeat_interleave(num_triplets)
            return torch.cat([safe, unsafe]), {CONTRASTIVE_ROLE_KEY: role}
        index = torch.cat(
            [
                partition.draw(SAFE, required_safe, generator, distinct=False),
                partition.draw(UNSAFE, required_unsafe, generator, distinct=False),
            ]
        )
        return index[torch.randperm(batch_size, generator=generator)], {}

    def _sample_graded(
        self, partition: _SafetyPartition, num_triplets: int, generator
    ) -> tuple[torch.Tensor, dict]:
        eligible = self._anchor_strata(num_triplets)
        anchor_stratum = eligible[int(torch.randint(len(eligible), (1,), generator=generator))]
        same = partition.draw(anchor_stratum, 2 * num_triplets, generator, distinct=True)
        others = [k for k in range(partition.num_strata) if k != anchor_stratum]
        counts = _even_split(
            num_triplets, [partition.size[k] for k in others], generator
        )
        negatives = [
            partition.draw(k, count, generator, distinct=True)
            for k, count in zip(others, counts)
            if count
        ]
        role = torch.arange(3, dtype=torch.long).repeat_interleave(num_triplets)
        return torch.cat([same, *negatives]), {CONTRASTIVE_ROLE_KEY: role}

    # ------------------------------------------------------------------ views
    @staticmethod
    def contrastive_view(
        replay_buffer: TensorDictReplayBuffer, num_triplets: int
    ) -> TensorDictReplayBuffer:
        """A read-only buffer over ``replay_buffer``'s storage that samples contrastive triplets.

        ``replay_buffer`` must use a :class:`SafeUnsafeSampler`: the view shares its partition
        (kept up to date by the main buffer's writes) and its random generator, so the data is
        stored once and a seeded main buffer seeds the view. ``view.sample()`` returns
        ``3 * num_triplets`` transitions with ``"contrastive_role"``; ``view.can_sample()``
        tells whether the strata are large enough. Write, empty and checkpoint through the main
        buffer only (the view holds no state of its own).
        """
        if int(num_triplets) < 1:
            raise ValueError(f"num_triplets must be >= 1, got {num_triplets}.")
        return SafeUnsafeSampler.view(replay_buffer, 3 * int(num_triplets), contrastive=True)

    @staticmethod
    def view(
        replay_buffer: TensorDictReplayBuffer,
        batch_size: int,
        *,
        contrastive: bool = False,
        unsafe_fraction: float | None = None,
    ) -> TensorDictReplayBuffer:
        """A read-only buffer over ``replay_buffer``'s storage with another sampling mode.

        Same sharing rules as :meth:`contrastive_view` (which is
        ``view(rb, 3 * B, contrastive=True)``); e.g. ``view(rb, 256, unsafe_fraction=0.5)``
        gives RL batches that oversample violations from the same storage.
        """
        sampler = replay_buffer.sampler
        if not isinstance(sampler, SafeUnsafeSampler):
            raise TypeError(
                "SafeUnsafeSampler views: the replay buffer's sampler must be a "
                f"SafeUnsafeSampler (it maintains the partition), got {type(sampler).__name__}."
            )
        owner = sampler._owner if sampler._owner is not None else sampler
        view_sampler = SafeUnsafeSampler(
            owner.label_key,
            contrastive=contrastive,
            unsafe_fraction=unsafe_fraction,
            bin_edges=owner.bin_edges,
        )
        view_sampler._owner = owner
        batch_size = int(batch_size)
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}.")
        if contrastive:
            view_sampler._requirements(batch_size)  # rejects a batch size that is not 3 * B
        return TensorDictReplayBuffer(
            storage=replay_buffer.storage,
            sampler=view_sampler,
            writer=_ViewWriter(),
            batch_size=batch_size,
        )

    # ------------------------------------------------------------------ state
    def _empty(self) -> None:
        # Emptying through any buffer empties the shared storage, hence the shared partition.
        partition = self.partition
        if partition is not None:
            partition.empty()

    def state_dict(self) -> dict[str, Any]:
        if self._owner is not None:
            return {}
        state = {
            "label_key": self.label_key,
            "partition": None if self._partition is None else self._partition.state_dict(),
        }
        if self.graded:
            state["bin_edges"] = list(self.bin_edges)
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        if self._owner is not None or not state_dict:
            return
        self._check_label_key(state_dict["label_key"], state_dict.get("bin_edges"))
        partition = state_dict["partition"]
        self._partition = None if partition is None else _SafetyPartition.from_state_dict(partition)

    def _check_label_key(self, saved_key, saved_edges=None) -> None:
        mine_edges = None if self.bin_edges is None else list(self.bin_edges)
        saved_edges = None if saved_edges is None else [float(e) for e in saved_edges]
        if saved_edges != mine_edges:
            raise ValueError(
                f"SafeUnsafeSampler: the saved partition was built with bin_edges "
                f"{saved_edges}, this sampler has {mine_edges}."
            )
        as_tuple = tuple(saved_key) if isinstance(saved_key, (list, tuple)) else (saved_key,)
        mine = self.label_key
        mine = tuple(mine) if isinstance(mine, (list, tuple)) else (mine,)
        if as_tuple != mine:
            raise ValueError(
                f"SafeUnsafeSampler: the saved partition was built from label {saved_key!r}, "
                f"this sampler reads {self.label_key!r}."
            )

    def dumps(self, path) -> None:
        if self._owner is not None:
            return
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        label_key = list(self.label_key) if isinstance(self.label_key, tuple) else self.label_key
        metadata = {"label_key": label_key}
        if self.graded:
            metadata["bin_edges"] = list(self.bin_edges)
        with open(path / "metadata.json", "w") as file:
            json.dump(metadata, file)
        if self._partition is not None:
            torch.save(self._partition.state_dict(), path / "partition.pt")

    def loads(self, path) -> None:
        if self._owner is not None:
            return
        path = Path(path)
        with open(path / "metadata.json") as file:
            metadata = json.load(file)
        self._check_label_key(metadata["label_key"], metadata.get("bin_edges"))
        partition_file = path / "partition.pt"
        self._partition = (
            _SafetyPartition.from_state_dict(torch.load(partition_file, weights_only=True))
            if partition_file.exists()
            else None
        )

    def __repr__(self) -> str:
        if self.contrastive:
            mode = "contrastive"
        elif self.unsafe_fraction is None:
            mode = "uniform"
        else:
            mode = f"unsafe_fraction={self.unsafe_fraction}"
        view = ", view" if self._owner is not None else ""
        if self.graded:
            counts = f"bin_edges={list(self.bin_edges)}, stratum_sizes={self.stratum_sizes}"
        else:
            counts = f"num_safe={self.num_safe}, num_unsafe={self.num_unsafe}"
        return f"{type(self).__name__}(label_key={self.label_key!r}, {mode}{view}, {counts})"


def _even_split(total: int, capacities: list[int], generator) -> list[int]:
    """``total`` draws split over strata as evenly as their ``capacities`` allow.

    Water-filling: each round gives every stratum with room an equal share of what is left
    (the remainder one each, to strata in random order), capped by its room; strata that fill
    drop out. Requires ``sum(capacities) >= total``.
    """
    counts = [0] * len(capacities)
    left = total
    while left > 0:
        open_strata = [k for k, cap in enumerate(capacities) if cap > counts[k]]
        share, extra = divmod(left, len(open_strata))
        order = torch.randperm(len(open_strata), generator=generator).tolist()
        for rank, position in enumerate(order):
            k = open_strata[position]
            give = min(capacities[k] - counts[k], share + (rank < extra))
            counts[k] += give
            left -= give
    return counts


class _ViewWriter(ImmutableDatasetWriter):
    """Writer of a contrastive view: the main buffer owns writes and emptying."""

    WRITING_ERR = (
        "this is a read-only contrastive view of another replay buffer; extend, add to or empty "
        "the main buffer instead (the view sees its writes)."
    )
