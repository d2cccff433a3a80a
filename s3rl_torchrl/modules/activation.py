"""ReLU whose backward reads its float output, so that compiled networks stay fast on CPU.

Eager, :func:`relu` and :class:`ReLU` are ``torch.relu`` and ``nn.ReLU``. Under
``torch.compile`` they trace a ReLU whose gradient is ``grad * sign(output)``.

Why: for ``torch.relu``, AOT autograd saves the backward's mask ``output <= 0`` as a **bool**
tensor, which takes a byte per element instead of four. It does so whenever the ReLU's output
is not needed otherwise, e.g. when a critic is evaluated with detached parameters for the actor
loss. On this machine's AVX-512 CPU (torch 2.13), inductor writes and reads bool tensors one
lane at a time through a generic 64-lane vector. Storing the mask of one ``[4, 256, 128]``
critic activation then costs ~1.1 ms against ~0.05 ms eager, and the forward and input-gradient
backward of a 3-layer critic ensemble 4.4 ms compiled against 1.2 ms eager; 1.1 ms with this
ReLU (``benchmarks/relu_mask.py``, ``docs/objectives.md``).

``sign(output)`` is computed from a float tensor that the backward saves anyway, so no bool
tensor crosses a kernel boundary. The gradient is the same as ``torch.relu``'s: ``grad`` where
the output is positive and 0 elsewhere.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = ["ReLU", "relu"]


class _ReLUFromOutput(torch.autograd.Function):
    generate_vmap_rule = True  # the loss's vmap critic modes may trace it under vmap

    @staticmethod
    def forward(x: Tensor) -> Tensor:
        return x.clamp_min(0)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(output)

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (output,) = ctx.saved_tensors
        return grad * output.sign()


def relu(x: Tensor, inplace: bool = False) -> Tensor:
    """``torch.relu`` (``relu_`` with ``inplace``). Under ``torch.compile`` it is a ReLU whose
    backward reads its float output instead of a saved bool mask. ``inplace`` is ignored then:
    inductor plans the buffers itself."""
    if torch.compiler.is_compiling():
        return _ReLUFromOutput.apply(x)
    return torch.relu_(x) if inplace else torch.relu(x)


class ReLU(nn.ReLU):
    """``nn.ReLU`` that calls :func:`relu`: the same module eager, and no bool masks in the
    graphs of ``torch.compile`` (module docstring). The package's network builders use it."""

    def forward(self, input: Tensor) -> Tensor:
        return relu(input, inplace=self.inplace)
