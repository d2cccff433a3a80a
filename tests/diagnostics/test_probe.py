"""The linear probe: high accuracy on separable embeddings, chance on label noise, NaN when a
class is missing; the replay-buffer variant is balanced, deterministic and RNG-neutral."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.diagnostics.probe import linear_probe, replay_probe


def test_separable_embeddings_are_read_off_almost_perfectly():
    rng = np.random.default_rng(0)
    safe = rng.random(1000) < 0.7
    z = rng.normal(size=(1000, 16))
    z[:, 3] += np.where(safe, 3.0, -3.0)  # one direction separates the classes
    result = linear_probe(z, safe, seed=0)
    assert result.accuracy > 0.98 and result.auc > 0.99
    assert result.n_test == 300 and result.n_safe == safe.sum()
    assert result.chance == pytest.approx(safe.mean(), abs=0.01)  # stratified split


def test_labels_unrelated_to_embeddings_give_chance():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(4000, 16))
    safe = rng.random(4000) < 0.5
    result = linear_probe(z, safe, seed=0)
    assert abs(result.accuracy - 0.5) < 0.05 and abs(result.auc - 0.5) < 0.05


def test_missing_class_gives_nan_not_an_error():
    z = np.random.default_rng(2).normal(size=(100, 4))
    result = linear_probe(z, np.ones(100, dtype=bool))
    assert math.isnan(result.accuracy) and math.isnan(result.auc) and not result.fitted
    assert result.n_unsafe == 0


def _buffer(n: int, unsafe_fraction: float) -> TensorDictReplayBuffer:
    gen = torch.Generator().manual_seed(0)
    obs = torch.randn(n, 6, generator=gen)
    safe = torch.rand(n, 1, generator=gen) >= unsafe_fraction
    obs[:, 0] += torch.where(safe[:, 0], 2.0, -2.0)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(n), sampler=SafeUnsafeSampler())
    rb.extend(TensorDict({"observation": obs, "next": {"safe": safe}}, batch_size=[n]))
    return rb


def _encoder() -> TensorDictModule:
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(6, 8), torch.nn.Tanh())
    return TensorDictModule(net, in_keys=["observation"], out_keys=["embedding"])


def test_replay_probe_balanced_deterministic_and_leaves_global_rngs_alone():
    rb, encoder = _buffer(5000, 0.1), _encoder()
    torch_state, np_state = torch.get_rng_state(), np.random.get_state()[1].copy()
    first = replay_probe(rb, encoder, seed=7, per_class=300)
    assert torch.equal(torch.get_rng_state(), torch_state)
    assert np.array_equal(np.random.get_state()[1], np_state)
    assert (first.n_safe, first.n_unsafe) == (300, 300)  # balanced: chance is 0.5
    assert first.chance == pytest.approx(0.5, abs=0.01)
    assert first.accuracy > 0.9  # observation[0] carries the label through the encoder
    assert replay_probe(rb, encoder, seed=7, per_class=300) == first


def test_replay_probe_without_unsafe_states_is_nan():
    result = replay_probe(_buffer(500, 0.0), _encoder(), seed=0)
    assert math.isnan(result.accuracy) and result.n_unsafe == 0
