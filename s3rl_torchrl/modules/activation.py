"""ReLU that keeps bool masks out of compiled graphs, so that compiled networks stay fast on CPU.

Eager, :func:`relu` and :class:`ReLU` are ``torch.relu`` and ``nn.ReLU``. Under
``torch.compile`` they trace ``x * sign(max(x, 0))`` with the factor detached: the same values
(``-0.0`` for ``x < 0``, equal to ``0.0``) and the same gradient as ``torch.relu`` (``grad``
where ``x > 0``, 0 elsewhere, 0 at 0 included), built from float tensors only.

Why: for ``torch.relu``, AOT autograd saves the backward's mask ``output <= 0`` as a **bool**
tensor, which takes a byte per element instead of four. It does so whenever the ReLU's output
is not needed otherwise, e.g. when a critic is evaluated with detached parameters for the actor
loss. On these machines' CPUs (torch 2.13), inductor writes and reads bool tensors one lane at
a time through a generic vector. Storing the mask of one ``[4, 256, 128]`` critic activation
then costs ~18x its eager time, and the forward and input-gradient backward of a 3-layer critic
ensemble ~3.8x (``research/studies/relu_mask.py``, ``docs/objectives.md``).

An earlier version was an ``autograd.Function`` whose backward read the float output. Under
``torch.vmap`` (several seeds in one compiled step: ``StackedSACLag``) inductor traced through
it to ``clamp_min``'s own backward and stored bool masks again. Plain differentiable ops leave
it nothing to trace through (``research/studies/relu_mask.py``, the ``critic_backward vmap`` rows).
``x = -inf`` gives ``nan`` instead of 0: a network whose pre-activations are infinite has
diverged anyway.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = ["ACTIVATIONS", "ReLU", "relu"]


def _relu_without_mask(x: Tensor) -> Tensor:
    # The factor is 1 where x > 0 and 0 elsewhere (sign(0) = 0); detached, so the backward is
    # grad * factor, a float product.
    return x * x.detach().clamp_min(0).sign()


def relu(x: Tensor, inplace: bool = False) -> Tensor:
    """``torch.relu`` (``relu_`` with ``inplace``). Under ``torch.compile`` it is a ReLU made of
    float ops, with no bool mask saved for the backward. ``inplace`` is ignored then: inductor
    plans the buffers itself."""
    if torch.compiler.is_compiling():
        return _relu_without_mask(x)
    return torch.relu_(x) if inplace else torch.relu(x)


class ReLU(nn.ReLU):
    """``nn.ReLU`` that calls :func:`relu`: the same module eager, and no bool masks in the
    graphs of ``torch.compile`` (module docstring). The package's network builders use it."""

    def forward(self, input: Tensor) -> Tensor:
        return relu(input, inplace=self.inplace)


#: The activations a run's networks can use (``network.activation``), by config name.
ACTIVATIONS: dict[str, type[nn.Module]] = {
    "relu": ReLU,  # nn.ReLU that stays fast under torch.compile (above)
    "tanh": nn.Tanh,
    "elu": nn.ELU,
    "silu": nn.SiLU,
}
