"""``SafeUnsafeSampler``: partition invariants against an independent model of the ring buffer,
batch composition (Algorithm 2), uniformity within strata, skip condition and state round-trips."""

from __future__ import annotations

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats
from tensordict import TensorDict
from torchrl.data import (
    LazyMemmapStorage,
    LazyTensorStorage,
    RandomSampler,
    TensorDictReplayBuffer,
)

from s3rl_torchrl.data import SafeUnsafeSampler, StratumTooSmallError
from s3rl_torchrl.data.sampler import SAFE, UNSAFE


def transitions(safe: list[bool], start: int = 0) -> TensorDict:
    """Transitions whose observation is a running id, so a sampled row names its write."""
    n = len(safe)
    return TensorDict(
        {
            "observation": torch.arange(start, start + n, dtype=torch.float32).unsqueeze(-1),
            "next": {
                "safe": torch.tensor(safe, dtype=torch.bool).reshape(n, 1),
                "cost": (~torch.tensor(safe, dtype=torch.bool)).float().reshape(n, 1),
            },
        },
        batch_size=[n],
    )


def make_buffer(capacity: int, seed: int | None = 0, storage_cls=LazyTensorStorage, **kwargs):
    sampler = SafeUnsafeSampler(**kwargs)
    generator = None if seed is None else torch.Generator().manual_seed(seed)
    return TensorDictReplayBuffer(
        storage=storage_cls(capacity), sampler=sampler, generator=generator, batch_size=None
    )


class RingModel:
    """What a round-robin buffer holds after a sequence of writes, in plain Python."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.slots: list[bool | None] = [None] * capacity
        self.cursor = 0

    def extend(self, labels: list[bool]) -> None:
        for label in labels:
            self.slots[self.cursor] = label
            self.cursor = (self.cursor + 1) % self.capacity

    def empty(self) -> None:
        self.slots = [None] * self.capacity
        self.cursor = 0

    def indices(self, label: bool) -> set[int]:
        return {i for i, value in enumerate(self.slots) if value is label}


def partition_sets(sampler: SafeUnsafeSampler) -> tuple[set[int], set[int]]:
    partition = sampler.partition
    if partition is None:
        return set(), set()
    safe = partition.members[SAFE][: partition.size[SAFE]].tolist()
    unsafe = partition.members[UNSAFE][: partition.size[UNSAFE]].tolist()
    assert len(set(safe)) == len(safe) and len(set(unsafe)) == len(unsafe)
    # every member knows where it sits
    for stratum, members in ((SAFE, safe), (UNSAFE, unsafe)):
        for position, slot in enumerate(members):
            assert partition.position[slot] == position
            assert partition.label[slot] == stratum
    return set(safe), set(unsafe)


# ---------------------------------------------------------------- partition invariants
writes = st.lists(
    st.one_of(
        st.lists(st.booleans(), min_size=1, max_size=30).map(lambda labels: ("extend", labels)),
        st.booleans().map(lambda label: ("add", [label])),
        st.just(("empty", [])),
    ),
    min_size=1,
    max_size=25,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(capacity=st.integers(1, 12), operations=writes)
def test_partition_matches_ring_model_under_wraparound(capacity, operations):
    rb = make_buffer(capacity)
    model = RingModel(capacity)
    for kind, labels in operations:
        if kind == "extend":
            rb.extend(transitions(labels))
        elif kind == "add":
            rb.add(transitions(labels)[0])
        else:
            rb.empty()
        if kind == "empty":
            model.empty()
        else:
            model.extend(labels)
        safe, unsafe = partition_sets(rb.sampler)
        assert safe == model.indices(True)
        assert unsafe == model.indices(False)
        assert rb.sampler.num_safe + rb.sampler.num_unsafe == len(rb)


def test_overwrite_moves_slot_between_strata():
    rb = make_buffer(4)
    rb.extend(transitions([True] * 4))
    assert (rb.sampler.num_safe, rb.sampler.num_unsafe) == (4, 0)
    rb.extend(transitions([False, False]))  # overwrites slots 0 and 1
    assert partition_sets(rb.sampler) == ({2, 3}, {0, 1})
    rb.extend(transitions([True, False, True]))  # slots 2, 3, 0
    assert partition_sets(rb.sampler) == ({0, 2}, {1, 3})


def test_write_larger_than_capacity_keeps_what_storage_keeps():
    rb = make_buffer(3)
    rb.extend(transitions([True, True, True, False, True]))
    stored = rb.storage[:]["next", "safe"].squeeze(-1).tolist()
    safe, unsafe = partition_sets(rb.sampler)
    assert safe == {i for i, s in enumerate(stored) if s}
    assert unsafe == {i for i, s in enumerate(stored) if not s}


def test_writes_through_another_buffer_on_the_same_storage_are_seen():
    rb = make_buffer(10)
    other = TensorDictReplayBuffer(storage=rb.storage, sampler=RandomSampler())
    other.extend(transitions([True, False, False]))
    assert partition_sets(rb.sampler) == ({0}, {1, 2})


# ---------------------------------------------------------------- contrastive batches
def test_contrastive_batch_layout_and_disjointness():
    B = 16
    rb = make_buffer(500)
    labels = [i % 4 != 0 for i in range(500)]  # 375 safe, 125 unsafe
    rb.extend(transitions(labels))
    view = SafeUnsafeSampler.contrastive_view(rb, B)
    for _ in range(50):
        batch = view.sample()
        assert batch.batch_size == (3 * B,)
        role = batch["contrastive_role"]
        assert role.dtype == torch.long
        assert role.tolist() == [0] * B + [1] * B + [2] * B
        safe = batch["next", "safe"].squeeze(-1)
        assert safe[: 2 * B].all() and not safe[2 * B :].any()
        ids = batch["observation"].squeeze(-1).long().tolist()
        assert len(set(ids)) == 3 * B
        assert all(labels[i] for i in ids[: 2 * B]) and not any(labels[i] for i in ids[2 * B :])
        assert "priority_weight" not in batch.keys()


def test_contrastive_sampler_as_the_main_sampler():
    rb = make_buffer(60, contrastive=True)
    rb.extend(transitions([True] * 40 + [False] * 20))
    batch = rb.sample(30)
    assert batch["contrastive_role"].tolist() == [0] * 10 + [1] * 10 + [2] * 10
    with pytest.raises(ValueError, match="3 \\* B"):
        rb.sample(31)


@pytest.mark.parametrize(
    ("num_safe", "num_unsafe", "possible"),
    [(20, 10, True), (19, 10, False), (20, 9, False), (0, 30, False), (30, 0, False)],
)
def test_skip_condition(num_safe, num_unsafe, possible):
    B = 10
    rb = make_buffer(100)
    rb.extend(transitions([True] * num_safe + [False] * num_unsafe))
    view = SafeUnsafeSampler.contrastive_view(rb, B)
    assert view.can_sample() is possible
    if possible:
        batch = view.sample()
        ids = batch["observation"].squeeze(-1).long()
        # at the boundary every safe and every unsafe transition is used exactly once
        assert sorted(ids[: 2 * B].tolist()) == list(range(num_safe))
        assert sorted(ids[2 * B :].tolist()) == list(range(num_safe, num_safe + num_unsafe))
    else:
        with pytest.raises(StratumTooSmallError) as info:
            view.sample()
        err = info.value
        assert (err.num_safe, err.num_unsafe) == (num_safe, num_unsafe)
        assert (err.required_safe, err.required_unsafe) == (2 * B, B)


def test_empty_buffer_cannot_sample():
    rb = make_buffer(10)
    view = SafeUnsafeSampler.contrastive_view(rb, 2)
    assert not view.can_sample()
    assert not rb.can_sample(4)


# ---------------------------------------------------------------- uniformity
def _chisquare_uniform(counts: torch.Tensor) -> float:
    return stats.chisquare(counts.double().numpy()).pvalue


@pytest.mark.parametrize("B", [10, 20])  # 10: rejection draws; 20: permutation draws
def test_contrastive_draws_are_uniform_within_each_stratum(B):
    num_safe, num_unsafe = 150, 50
    rb = make_buffer(num_safe + num_unsafe, seed=123)
    rb.extend(transitions([True] * num_safe + [False] * num_unsafe))
    view = SafeUnsafeSampler.contrastive_view(rb, B)
    anchor_counts = torch.zeros(num_safe)
    positive_counts = torch.zeros(num_safe)
    negative_counts = torch.zeros(num_unsafe)
    same_pair = 0
    for _ in range(1500):
        ids = view.sample()["observation"].squeeze(-1).long()
        anchor_counts += torch.bincount(ids[:B], minlength=num_safe)
        positive_counts += torch.bincount(ids[B : 2 * B], minlength=num_safe)
        negative_counts += torch.bincount(ids[2 * B :] - num_safe, minlength=num_unsafe)
        # pairing at random: slot ids of a pair are as often in the same order as not
        same_pair += int((ids[:B] < ids[B : 2 * B]).sum())
    for counts in (anchor_counts, positive_counts, negative_counts):
        assert _chisquare_uniform(counts) > 1e-3
    assert stats.binomtest(same_pair, 1500 * B).pvalue > 1e-3


def test_stratified_mode_fraction_and_uniformity():
    num_safe, num_unsafe, batch_size = 90, 30, 40
    rb = make_buffer(num_safe + num_unsafe, seed=7, unsafe_fraction=0.5)
    rb.extend(transitions([True] * num_safe + [False] * num_unsafe))
    counts = torch.zeros(num_safe + num_unsafe)
    for _ in range(1000):
        batch = rb.sample(batch_size)
        assert int((~batch["next", "safe"]).sum()) == 20  # round(0.5 * 40)
        counts += torch.bincount(batch["observation"].squeeze(-1).long(), minlength=120)
    assert _chisquare_uniform(counts[:num_safe]) > 1e-3
    assert _chisquare_uniform(counts[num_safe:]) > 1e-3
    # oversampling: an unsafe slot is drawn (20/30) / (20/90) = 3x as often as a safe one
    ratio = counts[num_safe:].mean() / counts[:num_safe].mean()
    assert abs(ratio.item() - 3.0) < 0.1


def test_uniform_mode_is_uniform_over_the_buffer():
    rb = make_buffer(100, seed=3)
    rb.extend(transitions([i % 3 == 0 for i in range(100)]))
    counts = torch.zeros(100)
    for _ in range(500):
        counts += torch.bincount(rb.sample(64)["observation"].squeeze(-1).long(), minlength=100)
    assert _chisquare_uniform(counts) > 1e-3


def test_stratified_view_shares_the_main_partition():
    rb = make_buffer(60, seed=2)
    rb.extend(transitions([True] * 50 + [False] * 10))
    oversampled = SafeUnsafeSampler.view(rb, 20, unsafe_fraction=0.5)
    assert int((~oversampled.sample()["next", "safe"]).sum()) == 10
    rb.extend(transitions([False] * 10, start=100))  # slots 0..9 become unsafe
    assert (oversampled.sampler.num_safe, oversampled.sampler.num_unsafe) == (40, 20)
    ids = torch.cat([oversampled.sample()["observation"].squeeze(-1) for _ in range(20)])
    assert (ids >= 100).any() and not ((ids >= 0) & (ids < 10)).any()
    with pytest.raises(ValueError, match="3 \\* B"):
        SafeUnsafeSampler.view(rb, 20, contrastive=True)


def test_stratified_mode_needs_each_requested_stratum():
    rb = make_buffer(20, unsafe_fraction=0.5)
    rb.extend(transitions([True] * 20))
    assert not rb.can_sample(8)
    with pytest.raises(StratumTooSmallError):
        rb.sample(8)
    only_safe = make_buffer(20, unsafe_fraction=0.0)
    only_safe.extend(transitions([True] * 20))
    assert only_safe.sample(8)["next", "safe"].all()


# ---------------------------------------------------------------- RNG and state
def _sequence(rb, view, n=5):
    return [rb.sample(8)["index"].tolist() for _ in range(n)] + [
        view.sample()["index"].tolist() for _ in range(n)
    ]


def test_seeded_buffers_reproduce_and_view_uses_the_main_generator():
    data = transitions([i % 3 != 0 for i in range(90)])
    runs = []
    for seed in (11, 11, 12):
        rb = make_buffer(90, seed=seed)
        rb.extend(data)
        runs.append(_sequence(rb, SafeUnsafeSampler.contrastive_view(rb, 5)))
    assert runs[0] == runs[1]
    assert runs[0] != runs[2]


def _filled_buffer(storage_cls=LazyTensorStorage, **kwargs):
    rb = make_buffer(50, seed=5, storage_cls=storage_cls, **kwargs)
    generator = torch.Generator().manual_seed(0)
    for step in range(7):  # 7 x 13 = 91 writes into 50 slots: wrapped
        labels = (torch.rand(13, generator=generator) > 0.4).tolist()
        rb.extend(transitions(labels, start=13 * step))
    return rb


def _assert_same_partition(a: SafeUnsafeSampler, b: SafeUnsafeSampler):
    assert partition_sets(a) == partition_sets(b)
    for stratum in (SAFE, UNSAFE):  # same order, hence the same future draws
        size = a.partition.size[stratum]
        assert torch.equal(a.partition.members[stratum][:size], b.partition.members[stratum][:size])


def test_state_dict_round_trip():
    rb = _filled_buffer()
    state = rb.state_dict()
    restored = make_buffer(50, seed=999)
    restored_view = SafeUnsafeSampler.contrastive_view(restored, 6)  # made before loading
    restored.load_state_dict(state)
    _assert_same_partition(rb.sampler, restored.sampler)
    view = SafeUnsafeSampler.contrastive_view(rb, 6)
    assert _sequence(rb, view) == _sequence(restored, restored_view)
    more = transitions([False] * 9, start=1000)
    rb.extend(more)
    restored.extend(more)
    _assert_same_partition(rb.sampler, restored.sampler)


def test_dumps_loads_round_trip_memmap(tmp_path):
    rb = _filled_buffer(LazyMemmapStorage)
    rb.dumps(tmp_path / "rb")
    restored = make_buffer(50, seed=999, storage_cls=LazyMemmapStorage)
    restored.loads(tmp_path / "rb")
    _assert_same_partition(rb.sampler, restored.sampler)
    view, restored_view = (SafeUnsafeSampler.contrastive_view(b, 6) for b in (rb, restored))
    assert _sequence(rb, view) == _sequence(restored, restored_view)


def test_load_rejects_other_label_key():
    state = _filled_buffer().state_dict()
    other = TensorDictReplayBuffer(
        storage=LazyTensorStorage(50), sampler=SafeUnsafeSampler(label_key="is_safe")
    )
    with pytest.raises(ValueError, match="label"):
        other.load_state_dict(state)


def test_empty_resets_the_partition():
    rb = _filled_buffer()
    view = SafeUnsafeSampler.contrastive_view(rb, 3)
    rb.empty()
    assert (rb.sampler.num_safe, rb.sampler.num_unsafe) == (0, 0)
    assert not view.can_sample()
    rb.extend(transitions([False, True, True, False, True, True, False, True, True, True]))
    assert partition_sets(rb.sampler) == ({1, 2, 4, 5, 7, 8, 9}, {0, 3, 6})
    assert view.can_sample()


# ---------------------------------------------------------------- guards
def test_storage_filled_behind_the_samplers_back_is_detected_and_rebuilt():
    storage = LazyTensorStorage(30)
    TensorDictReplayBuffer(storage=storage).extend(transitions([True] * 20 + [False] * 10))
    rb = TensorDictReplayBuffer(storage=storage, sampler=SafeUnsafeSampler(contrastive=True))
    with pytest.raises(RuntimeError, match="rebuild"):
        rb.sample(9)
    rb.sampler.rebuild(storage)
    assert partition_sets(rb.sampler) == (set(range(20)), set(range(20, 30)))
    assert rb.sample(9)["contrastive_role"].tolist() == [0] * 3 + [1] * 3 + [2] * 3


def test_direct_item_assignment_needs_mark_update():
    rb = make_buffer(6)
    rb.extend(transitions([True] * 6))
    rb[torch.tensor([1, 4])] = transitions([False, False])  # bypasses the writer
    rb.mark_update(torch.tensor([1, 4]))
    assert partition_sets(rb.sampler) == ({0, 2, 3, 5}, {1, 4})


def test_view_is_read_only():
    rb = make_buffer(10)
    view = SafeUnsafeSampler.contrastive_view(rb, 2)
    with pytest.raises(RuntimeError, match="main buffer"):
        view.extend(transitions([True]))
    with pytest.raises(RuntimeError, match="main buffer"):
        view.empty()


def test_bad_configuration_errors():
    with pytest.raises(ValueError, match="unsafe_fraction"):
        SafeUnsafeSampler(unsafe_fraction=1.5)
    with pytest.raises(ValueError, match="unsafe_fraction"):
        SafeUnsafeSampler(unsafe_fraction=0.5, contrastive=True)
    with pytest.raises(TypeError, match="SafeUnsafeSampler"):
        SafeUnsafeSampler.contrastive_view(TensorDictReplayBuffer(storage=LazyTensorStorage(5)), 2)
    with pytest.raises(ValueError, match="num_triplets"):
        SafeUnsafeSampler.contrastive_view(make_buffer(5), 0)


def test_bad_data_errors():
    missing = TensorDictReplayBuffer(
        storage=LazyTensorStorage(5), sampler=SafeUnsafeSampler(label_key="is_safe")
    )
    with pytest.raises(KeyError, match="is_safe.*CostLabel"):
        missing.extend(transitions([True, False]))
    not_bool = TensorDictReplayBuffer(
        storage=LazyTensorStorage(5), sampler=SafeUnsafeSampler(label_key=("next", "cost"))
    )
    with pytest.raises(TypeError, match="bool"):
        not_bool.extend(transitions([True, False]))
    # The advice names both ways a collector's [num_envs, time] batch goes in: unflattened
    # into a buffer with an n-step transform (it flattens after building each env's windows),
    # flattened into one without.
    advice = (
        r"With an n-step transform in the buffer \(make_nstep_transform\), extend with the "
        r"collector's unflattened \[num_envs, time\] batch, `rb.extend\(data\)`.*Without one, "
        r"flatten it first: `rb.extend\(data.reshape\(-1\)\)`"
    )
    unflattened = TensorDictReplayBuffer(storage=LazyTensorStorage(10), sampler=SafeUnsafeSampler())
    with pytest.raises(ValueError, match="one transition with one label.*" + advice):
        unflattened.extend(transitions([True] * 6).reshape(2, 3))  # 2 slots of 3 steps each
    two_dim = TensorDictReplayBuffer(
        storage=LazyTensorStorage(10, ndim=2), sampler=SafeUnsafeSampler()
    )
    with pytest.raises(ValueError, match="1-D storage.*default ndim=1.*" + advice):
        two_dim.extend(transitions([True] * 4).reshape(2, 2))


def test_with_env_data():
    from s3rl_torchrl.envs import make_env

    env = make_env("SafetySwimmerVelocity-v0", seed=0)
    rollout = env.rollout(120, break_when_any_done=False)
    env.close()
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100), sampler=SafeUnsafeSampler())
    rb.extend(rollout)
    kept_costs = rollout["next", "cost"][-100:].squeeze(-1)  # 120 writes into 100 slots
    assert rb.sampler.num_unsafe == int((kept_costs > 0).sum())
    assert rb.sampler.num_safe == int((kept_costs == 0).sum())
