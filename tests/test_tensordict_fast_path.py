"""The package's fast path in ``TensorDict.from_any``: what tensordict's own returns, sooner."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule

import s3rl_torchrl  # noqa: F401  (installs the fast path)
from s3rl_torchrl import _tensordict_fast_path

original = _tensordict_fast_path._original_from_any


def test_the_package_installs_it_once():
    installed = TensorDictBase.from_any.__func__
    # The fast path in front of tensordict's own function, never in front of another fast path
    # (the package may be imported anew, e.g. by tests that clear sys.modules).
    assert installed.tensordict_from_any is original
    assert not hasattr(original, "tensordict_from_any")
    _tensordict_fast_path.install()
    assert TensorDictBase.from_any.__func__ is installed


@pytest.mark.parametrize(
    "tensor", [torch.arange(6.0).reshape(2, 3), torch.tensor(1.5), torch.nn.Parameter(torch.ones(2))]
)
def test_a_tensor_comes_back_as_tensordict_returns_it(tensor):
    assert original(TensorDict, tensor) is tensor  # tensordict's own: the tensor itself
    assert TensorDict.from_any(tensor) is tensor


@dataclass
class Pair:
    a: torch.Tensor
    b: torch.Tensor


@pytest.mark.parametrize(
    "make",
    [
        lambda: {"a": torch.ones(3, 2), "b": {"c": torch.zeros(3)}},
        lambda: (torch.ones(3), torch.zeros(3)),
        lambda: Pair(torch.ones(3), torch.zeros(3)),
        lambda: TensorDict({"a": torch.ones(3)}, [3]),
    ],
    ids=["dict", "tuple", "dataclass", "tensordict"],
)
def test_everything_else_goes_to_tensordicts_own(make):
    ours, theirs = TensorDict.from_any(make(), auto_batch_size=True), original(
        TensorDict, make(), auto_batch_size=True
    )
    assert type(ours) is type(theirs)
    assert ours.batch_size == theirs.batch_size
    assert (ours == theirs).all()


def test_a_module_writes_its_outputs_as_before():
    module = TensorDictModule(lambda x: (2 * x, x + 1), in_keys=["x"], out_keys=["y", ("z", "w")])
    out = module(TensorDict({"x": torch.arange(4.0)}, [4]))
    torch.testing.assert_close(out["y"], 2 * torch.arange(4.0))
    torch.testing.assert_close(out["z", "w"], torch.arange(4.0) + 1)
