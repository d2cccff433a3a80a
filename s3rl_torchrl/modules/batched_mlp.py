"""``N`` critics of one torchrl ``MLP`` architecture as one chain of batched matmuls.

``SACLagLoss`` evaluates its reward and cost critics this way (``critic_eval="batched_mlp"``,
docs/objectives.md): the same numbers as vmapping the module over stacked parameters, minus
the functional-call and vmap overhead that dominates at RL sizes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torchrl.modules import MLP, ValueOperator

from s3rl_torchrl.modules.activation import ReLU, relu

__all__ = ["BatchedMLP"]

# Elementwise activations: applying them to [N, batch, features] equals applying them per net.
_ELEMENTWISE = (
    ReLU,
    nn.ReLU,
    nn.ReLU6,
    nn.LeakyReLU,
    nn.ELU,
    nn.SELU,
    nn.CELU,
    nn.GELU,
    nn.SiLU,
    nn.Mish,
    nn.Tanh,
    nn.Sigmoid,
    nn.Softplus,
    nn.Identity,
)


class BatchedMLP:
    """``N`` critics of one torchrl ``MLP`` architecture as a chain of batched matmuls.

    Equivalent to vmapping the module over stacked parameters ``[N, ...]``, minus the
    functional-call and vmap overhead that dominates at RL sizes (``docs/objectives.md``).
    Built only for ``TensorDictModule(MLP)`` critics whose layers are ``nn.Linear`` and
    elementwise activations; anything else (dropout, norms, custom modules) uses vmap.
    """

    def __init__(self, in_keys, layers):
        self.in_keys = list(in_keys)
        self.layers = layers  # ("linear", weight key, bias key) or ("act", module)

    @classmethod
    def from_module(cls, module, params: TensorDictBase) -> BatchedMLP | None:
        if type(module) not in (TensorDictModule, ValueOperator) or len(module.out_keys) != 1:
            return None
        mlp = module.module
        if type(mlp) is not MLP or getattr(mlp, "_reshape_out", True):
            return None
        flat_keys = set(params.flatten_keys().keys())
        layers, expected = [], set()
        for name, layer in mlp.named_children():
            if type(layer) is nn.Linear:
                if layer.bias is None:
                    return None
                weight, bias = ("module", name, "weight"), ("module", name, "bias")
                layers.append(("linear", weight, bias))
                expected.update((".".join(weight), ".".join(bias)))
            elif type(layer) in _ELEMENTWISE:
                layers.append(("act", layer))
            else:
                return None
        if flat_keys != expected or not layers or layers[-1][0] != "linear":
            return None
        last_bias = params.get(layers[-1][2])
        if last_bias.shape[-1] != 1:
            return None
        return cls(module.in_keys, layers)

    @staticmethod
    def _leaf(parts: Sequence[TensorDictBase], key) -> Tensor:
        # Concatenating leaf by leaf costs a few microseconds; a TensorDict-level cat of the
        # reward and cost parameters costs ~0.1 ms per call, a few % of an eager step.
        if len(parts) == 1:
            return parts[0].get(key)
        return torch.cat([part.get(key) for part in parts], 0)

    def _rest(self, x: Tensor, parts: Sequence[TensorDictBase], batch_shape) -> Tensor:
        """The layers after the first linear one: ``[N, M, H] -> [N, *batch]``."""
        for layer in self.layers[1:]:
            if layer[0] == "act":
                # In place where autograd allows it (no op before ReLU saves its output): fewer
                # [N, batch, width] temporaries, which measurably cost page faults on CPU.
                # Compiled, `relu` keeps bool masks out of the graph (modules/activation.py).
                x = relu(x, inplace=True) if type(layer[1]) in (nn.ReLU, ReLU) else layer[1](x)
            else:
                weight, bias = self._leaf(parts, layer[1]), self._leaf(parts, layer[2])
                x = torch.baddbmm(bias.unsqueeze(-2), x, weight.transpose(-1, -2))
        return x.squeeze(-1).reshape(x.shape[0], *batch_shape)

    def __call__(self, td: TensorDictBase, parts: Sequence[TensorDictBase]) -> Tensor:
        """Values ``[N, *batch]`` of the critics whose stacked parameters are ``parts``
        (several parameter sets are concatenated along the critic dimension)."""
        x = torch.cat([td.get(key) for key in self.in_keys], -1)
        batch_shape = x.shape[:-1]
        weight, bias = self._leaf(parts, self.layers[0][1]), self._leaf(parts, self.layers[0][2])
        # The input is shared by all critics: broadcast [M, F] @ [N, F, H].
        x = torch.matmul(x.reshape(-1, x.shape[-1]), weight.transpose(-1, -2))
        return self._rest(x.add_(bias.unsqueeze(-2)), parts, batch_shape)

    def first_layer_term(
        self, td: TensorDictBase, parts: Sequence[TensorDictBase], keys, *, bias: bool
    ) -> Tensor:
        """``sum_k x_k W1[:, cols_k]^T`` (+ ``b1``) over the inputs ``keys``: ``[N, M, H]``.

        The first layer of ``Q(concat(x_1, ..., x_K))`` is a sum of per-input terms; computing
        them apart lets the actor loss (a) reuse the observation term of the critic loss and (b)
        backpropagate into the action columns only instead of the whole input.
        """
        weight = self._leaf(parts, self.layers[0][1])
        out, start = None, 0
        for key in self.in_keys:
            x = td.get(key)
            width = x.shape[-1]
            if key in keys:
                cols = weight[..., start : start + width].transpose(-1, -2)
                term = torch.matmul(x.reshape(-1, width), cols)
                out = term if out is None else out + term
            start += width
        if bias:
            b1 = self._leaf(parts, self.layers[0][2]).unsqueeze(-2)
            out = b1 if out is None else out + b1
        return out

    def from_first_layer(self, h: Tensor, parts: Sequence[TensorDictBase], batch_shape) -> Tensor:
        """Values ``[N, *batch]`` from the pre-activation of the first layer ``[N, M, H]``."""
        return self._rest(h, parts, batch_shape)
