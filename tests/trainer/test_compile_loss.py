"""``compile_loss`` drops dynamo's guards on module attributes: what changes during training
(tensors, changed in place) must still reach the compiled loss, with no recompile."""

from __future__ import annotations

import pytest
import torch

from s3rl_torchrl.trainer import compile_loss
from tests.objectives.test_sac_lag import make_batch, make_loss


@pytest.mark.slow  # torch.compile of the loss
def test_in_place_changes_reach_the_compiled_loss_without_recompiling():
    loss, *_ = make_loss()
    other, *_ = make_loss()
    with torch.no_grad():  # other weights than `loss`'s, to load below
        for value in other.parameters():
            value.add_(0.1 * torch.randn_like(value))
    compiled = compile_loss(loss)
    batch = make_batch()
    torch.manual_seed(0)
    compiled(batch.copy())

    def change_lambda():
        loss.set_lagrangian(2.5)

    def change_alpha():
        with torch.no_grad():
            loss.log_alpha.add_(1.0)

    def load_weights():  # a checkpoint restored into the running loss
        loss.load_state_dict(other.state_dict())

    for change in (change_lambda, change_alpha, load_weights):
        change()
        with torch._dynamo.config.patch(error_on_recompile=True):
            torch.manual_seed(0)
            out = compiled(batch.copy())
        torch.manual_seed(0)
        eager = loss(batch.copy())
        for key in ("loss_actor", "loss_qvalue", "loss_cost_qvalue", "loss_alpha"):
            torch.testing.assert_close(out[key], eager[key], msg=f"{key} after {change.__name__}")


@pytest.mark.slow
def test_tensordicts_memo_of_types_does_not_recompile_the_loss():
    # tensordict memoises its type checks in a dict whose length dynamo guards; an eager vmap
    # (the critic diagnostics, at an epoch's end) adds `tuple` to it after the first compile.
    from tensordict import utils

    loss, *_ = make_loss()
    compiled = compile_loss(loss)
    batch = make_batch()
    compiled(batch.copy())

    class NewType:
        pass

    before = len(utils._TENSORCLASS_MEMO)
    utils._is_tensorclass(NewType)
    assert len(utils._TENSORCLASS_MEMO) == before + 1
    loss.critic_values(batch)  # eager
    with torch._dynamo.config.patch(error_on_recompile=True):
        compiled(batch.copy())


@pytest.mark.slow
def test_grad_mode_is_still_guarded():
    # Global state keeps its guards: the loss called without grad is traced anew, no stale graph.
    loss, *_ = make_loss()
    compiled = compile_loss(loss)
    batch = make_batch()
    compiled(batch.copy())
    with torch.no_grad():
        out = compiled(batch.copy())
    assert not out["loss_actor"].requires_grad


@pytest.mark.slow
def test_the_loss_forward_is_one_graph_without_breaks():
    # A graph break splits the compiled step into pieces with Python between them (issue 28's
    # "one compiled region"); torch._dynamo.explain counts them without running the compiler.
    loss, *_ = make_loss()
    explained = torch._dynamo.explain(loss)(make_batch())
    assert explained.graph_break_count == 0, [b.reason for b in explained.break_reasons]
    assert explained.graph_count == 1
