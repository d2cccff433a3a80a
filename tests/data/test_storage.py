"""GatherStorage: the rows torchrl's LazyTensorStorage gives, for every index it is given."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, RandomSampler, TensorDictReplayBuffer

from s3rl_torchrl.data import GatherStorage


def filled(storage_class, capacity: int = 50, rows: int = 30):
    g = torch.Generator().manual_seed(0)
    data = TensorDict(
        {
            "observation": torch.randn(rows, 4, generator=g),
            "steps": torch.randint(0, 5, (rows, 1), generator=g),
            "next": {"safe": torch.rand(rows, 1, generator=g) > 0.5},
        },
        [rows],
    )
    storage = storage_class(capacity)
    storage.set(torch.arange(rows), data)
    return storage


@pytest.mark.parametrize(
    "index",
    [
        torch.tensor([3, 0, 29, 3]),
        torch.tensor([7], dtype=torch.int32),
        torch.tensor([-1, 2]),  # negative: torchrl's own indexing
        5,
        slice(2, 9),
        [1, 4],
    ],
    ids=["tensor", "int32", "negative", "int", "slice", "list"],
)
def test_get_gives_lazy_tensor_storages_rows(index):
    ours, theirs = filled(GatherStorage).get(index), filled(LazyTensorStorage).get(index)
    assert ours.batch_size == theirs.batch_size
    assert (ours == theirs).all()


def test_rows_past_the_filled_part_are_refused_as_torchrl_refuses_them():
    with pytest.raises(IndexError):
        filled(LazyTensorStorage).get(torch.tensor([1, 40]))
    with pytest.raises(IndexError):
        filled(GatherStorage).get(torch.tensor([1, 40]))


def test_a_buffer_samples_the_same_batches_on_either_storage():
    batches = []
    for storage_class in (GatherStorage, LazyTensorStorage):
        buffer = TensorDictReplayBuffer(
            storage=storage_class(50), sampler=RandomSampler(), batch_size=8
        )
        buffer.extend(filled(LazyTensorStorage).get(slice(0, 30)))
        torch.manual_seed(3)
        batches.append([buffer.sample() for _ in range(3)])
    for ours, theirs in zip(*batches, strict=True):
        assert (ours == theirs).all()


def test_the_state_dict_is_lazy_tensor_storages():
    ours, theirs = filled(GatherStorage), filled(LazyTensorStorage)
    restored = GatherStorage(50)
    restored.load_state_dict(theirs.state_dict())
    assert (restored.get(torch.arange(30)) == ours.get(torch.arange(30))).all()
