"""The graded probe: held-out Spearman and R^2 of a linear regression, against numpy/scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.stats import spearmanr
from sklearn.model_selection import train_test_split
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.diagnostics import graded_probe, replay_graded_probe


def numpy_reference(z, y, seed, test_fraction=0.3):
    """Least squares with an intercept on the training part, scored by hand on the rest."""
    train_index, test_index = train_test_split(
        np.arange(len(y)), test_size=test_fraction, random_state=seed
    )
    design = np.c_[z[train_index], np.ones(len(train_index))]
    coef, *_ = np.linalg.lstsq(design, y[train_index], rcond=None)
    predicted = np.c_[z[test_index], np.ones(len(test_index))] @ coef
    truth = y[test_index]
    r2 = 1.0 - np.sum((truth - predicted) ** 2) / np.sum((truth - truth.mean()) ** 2)
    return spearmanr(predicted, truth).statistic, r2, len(train_index), len(test_index)


@pytest.mark.parametrize("seed", [0, 3])
def test_matches_numpy_least_squares_and_scipy_spearman(seed):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(200, 5))
    y = z @ np.array([1.0, -0.5, 0.0, 0.2, 0.0]) + 0.8 * rng.normal(size=200)
    result = graded_probe(z, y, seed=seed)
    spearman, r2, n_train, n_test = numpy_reference(z, y, seed)
    assert result.spearman == pytest.approx(spearman, abs=1e-9)
    assert result.r2 == pytest.approx(r2, abs=1e-9)
    assert (result.n_train, result.n_test) == (n_train, n_test) == (140, 60)


def test_a_linear_label_is_recovered_and_an_unrelated_one_is_not():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(500, 8))
    exact = graded_probe(z, 2.0 * z[:, 2] - z[:, 5] + 3.0)
    assert exact.r2 == pytest.approx(1.0, abs=1e-9) and exact.spearman == pytest.approx(1.0)
    noise = graded_probe(z, rng.normal(size=500))
    assert noise.r2 < 0.05 and abs(noise.spearman) < 0.15


def test_unfittable_inputs_give_nan():
    z = np.random.default_rng(2).normal(size=(50, 3))
    constant = graded_probe(z, np.ones(50))
    assert math.isnan(constant.r2) and math.isnan(constant.spearman) and not constant.fitted
    assert not graded_probe(z[:5], np.arange(5.0)).fitted
    with pytest.raises(ValueError, match="finite"):
        graded_probe(z, np.r_[np.nan, np.ones(49)])


def test_replay_probe_is_bin_balanced_deterministic_and_rng_neutral():
    n = 300
    generator = torch.Generator().manual_seed(0)
    obs = torch.randn(n, 4, generator=generator)
    label = torch.cat([torch.zeros(200), torch.linspace(0.6, 1.9, 80), torch.full((20,), 3.0)])
    label = label + 0.01 * obs[:, 0]  # the embedding (identity) carries the label
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(n),
        sampler=SafeUnsafeSampler(("next", "cost_to_go"), bin_edges=(0.5, 2.0)),
    )
    rb.extend(TensorDict({"observation": obs, "next": {"cost_to_go": label[:, None]}}, [n]))
    linear = torch.nn.Linear(4, 4, bias=False)
    with torch.no_grad():
        linear.weight.copy_(torch.eye(4))
    encoder = TensorDictModule(linear, in_keys=["observation"], out_keys=["z"])
    torch.manual_seed(123)
    before = torch.rand(1)
    torch.manual_seed(123)
    result = replay_graded_probe(rb, encoder, seed=7, label_key=("next", "cost_to_go"),
                                 bin_edges=(0.5, 2.0), per_bin=50)
    assert torch.rand(1) == before  # the global RNG was not used
    assert result.n_train + result.n_test == 50 + 50 + 20  # per bin, capped by the bin
    again = replay_graded_probe(rb, encoder, seed=7, label_key=("next", "cost_to_go"),
                                bin_edges=(0.5, 2.0), per_bin=50)
    assert (again.spearman, again.r2) == (result.spearman, result.r2)
    one_bin = replay_graded_probe(rb, encoder, seed=7, label_key=("next", "cost_to_go"),
                                  per_bin=1000)
    assert one_bin.n_train + one_bin.n_test == n
