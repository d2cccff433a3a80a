"""A fast path in ``TensorDict.from_any`` for plain tensors (tensordict 0.14.x).

Every ``TensorDictModule`` call writes each output through ``TensorDict.from_any(tensor)``
(``tensordict/nn/common.py``, ``_write_to_tensordict``). For a tensor, ``from_any`` falls
through its type checks to ``importlib.util.find_spec("pandas")`` and returns the tensor
unchanged; when pandas is not installed (it is not a dependency here) that lookup searches
``sys.path`` on every call: 33 us per module output here
(benchmarks/results/archive/2026-11-24/from_any_fast_path.json; 0.7 us with the fast path). The collector's policy
pays it 3 times per vector-env step, an eager SAC-Lag gradient step many times.

The patch returns a plain tensor at once, which is what ``from_any`` returns for it: no branch
of ``from_any`` converts a ``torch.Tensor`` (it is neither a tensor collection, a dict, a tuple,
a list, a dataclass, a structured numpy array, a pandas DataFrame nor an h5py File). Every
other input goes to tensordict's own ``from_any``. Applied once, on import of the package.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.base import is_tensor_collection

# tensordict's own function, also when the package is imported anew (tests that clear
# sys.modules) after an earlier import installed the fast path.
_installed = TensorDictBase.from_any.__func__
_original_from_any = getattr(_installed, "tensordict_from_any", _installed)


def _from_any(cls, obj, **kwargs):
    if isinstance(obj, torch.Tensor) and not is_tensor_collection(obj):
        return obj
    return _original_from_any(cls, obj, **kwargs)


_from_any.tensordict_from_any = _original_from_any


def install() -> None:
    """Route ``TensorDictBase.from_any`` (and so every subclass's) through the fast path, once."""
    if not hasattr(TensorDictBase.from_any.__func__, "tensordict_from_any"):
        TensorDictBase.from_any = classmethod(_from_any)
