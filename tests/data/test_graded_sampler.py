"""``SafeUnsafeSampler(bin_edges=...)``: strata by graded-label bin and graded triplets."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import LabelBinTooSmallError, SafeUnsafeSampler, StratumTooSmallError
from s3rl_torchrl.data.sampler import _even_split

KEY = ("next", "cost_to_go")
EDGES = (0.5, 2.0)  # bins [-inf, 0.5) | [0.5, 2.0) | [2.0, inf)


def graded_buffer(labels, capacity=None, seed=0):
    labels = torch.as_tensor(labels, dtype=torch.float32)
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(capacity or len(labels)),
        sampler=SafeUnsafeSampler(KEY, bin_edges=EDGES),
        generator=torch.Generator().manual_seed(seed),
    )
    rb.extend(data(labels))
    return rb


def data(labels):
    n = len(labels)
    return TensorDict(
        {"observation": torch.arange(n, dtype=torch.float32)[:, None],
         "next": {"cost_to_go": labels[:, None]}},
        batch_size=[n],
    )


def bin_by_hand(value):
    return 0 if value < 0.5 else (1 if value < 2.0 else 2)


def test_strata_are_the_label_bins_and_follow_overwrites():
    labels = [0.0, 0.5, 1.99, 2.0, 7.0, 0.49, 0.1, 3.0]
    rb = graded_buffer(labels, capacity=8)
    sampler = rb.sampler
    assert sampler.stratum_sizes == [3, 2, 3]  # edges open the bin above them
    partition = sampler.partition
    for k in range(3):
        members = set(partition.members[k][: partition.size[k]].tolist())
        assert members == {i for i, v in enumerate(labels) if bin_by_hand(v) == k}
    # the ring buffer wraps: slots 0..2 are overwritten with new labels
    rb.extend(data(torch.tensor([5.0, 5.0, 0.0])))
    new = [5.0, 5.0, 0.0] + labels[3:]
    assert sampler.stratum_sizes == [sum(bin_by_hand(v) == k for v in new) for k in range(3)]


def test_contrastive_batches_draw_by_label_distance():
    # 40 in bin 0, 12 in bin 1, 3 in bin 2.
    labels = [0.0] * 40 + [1.0] * 12 + [5.0] * 3
    rb = graded_buffer(labels)
    B = 6
    view = SafeUnsafeSampler.contrastive_view(rb, B)
    label_of = torch.tensor(labels)
    anchor_bins = set()
    for _ in range(30):
        batch = view.sample()
        index = batch["observation"].squeeze(-1).long()
        role = batch["contrastive_role"]
        assert role.tolist() == [0] * B + [1] * B + [2] * B
        bins = [bin_by_hand(float(label_of[i])) for i in index]
        anchor_bin = bins[0]
        anchor_bins.add(anchor_bin)
        assert set(bins[: 2 * B]) == {anchor_bin}  # anchors and positives: one bin
        assert anchor_bin not in bins[2 * B :]  # negatives: the other bins
        assert len(set(index[: 2 * B].tolist())) == 2 * B  # distinct
        assert len(set(index[2 * B :].tolist())) == B
        # only bin 0 (40 >= 12) and bin 1 (12 >= 12, others 43 >= 6) can give the anchors
        assert anchor_bin in (0, 1)
        negative_bins = bins[2 * B :]
        if anchor_bin == 0:  # split evenly over bins 1 and 2, bin 2 capped at its 3
            assert sorted(negative_bins) == [1, 1, 1, 2, 2, 2]
        else:
            assert sorted(negative_bins) == [0, 0, 0, 2, 2, 2]
    assert anchor_bins == {0, 1}


def test_even_split_by_hand():
    g = torch.Generator().manual_seed(0)
    assert _even_split(6, [10, 10], g) == [3, 3]
    # round 1: 2 each, bin 0 capped at 1; round 2: the one left goes to bin 1 or bin 2
    assert _even_split(6, [1, 10, 10], g) in ([1, 3, 2], [1, 2, 3])
    assert sorted(_even_split(5, [10, 10], g)) == [2, 3]
    assert _even_split(7, [2, 0, 9], g) == [2, 0, 5]


def test_too_small_bins_refuse_to_sample():
    rb = graded_buffer([0.0] * 10 + [5.0] * 2)
    view = SafeUnsafeSampler.contrastive_view(rb, 6)  # needs 12 in one bin
    assert not view.can_sample()
    with pytest.raises(LabelBinTooSmallError, match=r"\[10, 0, 2\]") as info:
        view.sample()
    assert isinstance(info.value, StratumTooSmallError)
    assert SafeUnsafeSampler.contrastive_view(rb, 2).can_sample()
    only_one_bin = graded_buffer([0.0] * 30)
    assert not SafeUnsafeSampler.contrastive_view(only_one_bin, 2).can_sample()


def test_state_round_trip_and_edges_checked(tmp_path):
    rb = graded_buffer([0.0, 1.0, 3.0, 0.2])
    state = rb.sampler.state_dict()
    fresh = SafeUnsafeSampler(KEY, bin_edges=EDGES)
    fresh.load_state_dict(state)
    assert fresh.stratum_sizes == [2, 1, 1]
    with pytest.raises(ValueError, match="bin_edges"):
        SafeUnsafeSampler(KEY, bin_edges=(1.0,)).load_state_dict(state)
    rb.sampler.dumps(tmp_path)
    loaded = SafeUnsafeSampler(KEY, bin_edges=EDGES)
    loaded.loads(tmp_path)
    assert loaded.stratum_sizes == [2, 1, 1]
    with pytest.raises(ValueError, match="bin_edges"):
        SafeUnsafeSampler(KEY).loads(tmp_path)


def test_argument_and_label_errors():
    with pytest.raises(ValueError, match="increasing"):
        SafeUnsafeSampler(KEY, bin_edges=(1.0, 1.0))
    with pytest.raises(ValueError, match="increasing"):
        SafeUnsafeSampler(KEY, bin_edges=())
    with pytest.raises(ValueError, match="graded form"):
        SafeUnsafeSampler(KEY, bin_edges=(1.0,), unsafe_fraction=0.5)
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(4), sampler=SafeUnsafeSampler(("next", "safe"), bin_edges=(1.0,))
    )
    with pytest.raises(TypeError, match="float"):
        rb.extend(TensorDict({"next": {"safe": torch.ones(4, 1, dtype=torch.bool)}}, [4]))
    with pytest.raises(ValueError, match="NaN"):
        graded_buffer([0.0, float("nan")])
