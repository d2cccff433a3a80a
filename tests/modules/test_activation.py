"""ReLU that keeps bool masks out of compiled graphs: same values and gradients as torch.relu,
eager and compiled, and no bool tensor saved for the backward."""

from __future__ import annotations

import pytest
import torch
from functorch.compile import make_boxed_func, min_cut_rematerialization_partition
from torch import nn
from torch._dynamo.backends.common import aot_autograd
from torch._inductor.decomposition import select_decomp_table

from s3rl_torchrl.modules import ReLU, build_qvalue_network, build_s3rl_actor, relu


def _two_layer(act, x, w1, w2):
    return (act(x @ w1) @ w2).square().sum()


def _inputs(requires_grad_weights: bool):
    g = torch.Generator().manual_seed(0)
    # Exact zeros among the pre-activations: the gradient at 0 must be 0, as torch.relu's.
    x = torch.randn(64, 8, generator=g)
    x[:4] = 0.0
    w1 = torch.randn(8, 16, generator=g)
    w1[:, :2] = 0.0
    w2 = torch.randn(16, 1, generator=g)
    x.requires_grad_()
    for w in (w1, w2):
        w.requires_grad_(requires_grad_weights)
    return x, w1, w2


def _grads(fn, act, requires_grad_weights):
    x, w1, w2 = _inputs(requires_grad_weights)
    out = fn(act, x, w1, w2)
    out.backward()
    leaves = [t for t in (x, w1, w2) if t.requires_grad]
    return out.detach(), [t.grad for t in leaves]


@pytest.mark.parametrize("requires_grad_weights", [True, False])
def test_eager_equals_torch_relu(requires_grad_weights):
    ref_out, ref_grads = _grads(_two_layer, torch.relu, requires_grad_weights)
    out, grads = _grads(_two_layer, relu, requires_grad_weights)
    torch.testing.assert_close(out, ref_out, rtol=0, atol=0)
    for got, want in zip(grads, ref_grads):
        torch.testing.assert_close(got, want, rtol=0, atol=0)


def test_inplace_and_module():
    x = torch.tensor([-1.0, 0.0, 2.0])
    y = relu(x, inplace=True)
    assert y is x and x.tolist() == [0.0, 0.0, 2.0]
    module = ReLU()
    assert isinstance(module, nn.ReLU)  # code that looks for nn.ReLU still finds it
    assert module(torch.tensor([-3.0, 4.0])).tolist() == [0.0, 4.0]


def _two_agents(act, x, w1, w2):
    """Two agents' copies under torch.vmap, as StackedSACLag runs several seeds' losses."""
    stack = [torch.stack([t, 2 * t]) for t in (x, w1, w2)]
    return torch.vmap(lambda *a: _two_layer(act, *a))(*stack).sum()


def _saved_dtypes(act, requires_grad_weights, fn=_two_layer):
    """dtypes of the tensors the compiled forward saves for the backward."""
    saved = []

    def forward_compiler(graph_module, example_inputs):
        (output_node,) = [n for n in graph_module.graph.nodes if n.op == "output"]
        saved.extend(
            n.meta["val"].dtype
            for n in output_node.args[0]
            if hasattr(n, "meta") and "val" in n.meta
        )
        return make_boxed_func(graph_module.forward)

    # Inductor's decompositions and partitioner decide what the forward saves; the graphs
    # then run uncompiled.
    backend = aot_autograd(
        fw_compiler=forward_compiler,
        bw_compiler=lambda gm, _: make_boxed_func(gm.forward),
        partition_fn=min_cut_rematerialization_partition,
        decompositions=select_decomp_table(),
    )
    torch._dynamo.reset()
    compiled = torch.compile(fn, backend=backend, fullgraph=True)
    out, grads = _grads(compiled, act, requires_grad_weights)
    return saved, out, grads


@pytest.mark.parametrize("fn", [_two_layer, _two_agents], ids=["one", "vmapped"])
@pytest.mark.parametrize("requires_grad_weights", [True, False])
def test_compiled_saves_no_bool_mask_and_matches_eager(requires_grad_weights, fn):
    ref_out, ref_grads = _grads(fn, torch.relu, requires_grad_weights)
    # torch.relu under AOT autograd: with frozen weights (the actor loss's critics) the backward
    # needs only the mask, which is saved as bool -- the slow case on CPU.
    torch_saved, _, _ = _saved_dtypes(torch.relu, requires_grad_weights, fn)
    if not requires_grad_weights:
        assert torch.bool in torch_saved
    saved, out, grads = _saved_dtypes(relu, requires_grad_weights, fn)
    assert torch.bool not in saved
    torch.testing.assert_close(out, ref_out)
    for got, want in zip(grads, ref_grads):
        torch.testing.assert_close(got, want)


def test_builders_use_it():
    critic = build_qvalue_network(3, 2, hidden=(4, 4))
    assert sum(type(m) is ReLU for m in critic.modules()) == 2
    from torchrl.data import Bounded

    actor = build_s3rl_actor(3, Bounded(-torch.ones(2), torch.ones(2), (2,)), hidden=(4, 4))
    assert sum(type(m) is ReLU for m in actor.modules()) == 2
    from s3rl_torchrl.modules import ACTIVATIONS  # the recipes' network.activation

    assert ACTIVATIONS["relu"] is ReLU
