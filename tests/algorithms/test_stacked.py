"""StackedSACLag (K agents, one vmapped update) against K separate SACLagLoss, Adams and lerps."""

from __future__ import annotations

import copy

import pytest
import torch
from tensordict import TensorDict

from s3rl_torchrl.algorithms import StackedSACLag, make_sac_lag_optimizers
from s3rl_torchrl.algorithms.stacked import NOISE_DRAWS, _normal_noise, draw_noise
from s3rl_torchrl.objectives import ForeachSoftUpdate, SACLagLoss
from tests.objectives.test_sac_lag import ACT, GAMMA, make_actor, make_batch, make_critics

K, BATCH = 3, 32
LR = {"actor_lr": 5e-4, "critic_lr": 1e-3, "alpha_lr": 3e-4}
TAU = 0.05


def make_losses(num_costs: int, fixed_alpha: bool = False) -> list[SACLagLoss]:
    """K agents with their own initial weights, alpha and lambda (as K seeds would have)."""
    losses = []
    for k in range(K):
        critics = make_critics(2, seed=10 * k + 1)
        costs = make_critics(2 * num_costs, cost=True, seed=10 * k + 3) if num_costs else None
        loss = SACLagLoss(
            make_actor(seed=10 * k),
            critics,
            costs,
            num_costs=num_costs,
            alpha_init=0.005 * (k + 1),
            fixed_alpha=fixed_alpha,
            lagrangian_init=0.5 * k if num_costs else 0.0,
        )
        loss.make_value_estimator(gamma=GAMMA)
        losses.append(loss)
    return losses


def make_batches(num_costs: int) -> TensorDict:
    return torch.stack([make_batch(BATCH, max(num_costs, 1), seed=100 + k) for k in range(K)])


def make_noise(seed: int = 7) -> torch.Tensor:
    torch.manual_seed(seed)
    return torch.stack([draw_noise(BATCH, ACT) for _ in range(K)])


def stacked_group(losses) -> StackedSACLag:
    return StackedSACLag(losses, LR["actor_lr"], LR["critic_lr"], LR["alpha_lr"], TAU)


def leaves(loss: SACLagLoss) -> dict:
    return {k: v for k, v in TensorDict.from_module(loss).flatten_keys().items()}


def single_step(loss: SACLagLoss, optimizers, updater, batch, noise) -> TensorDict:
    """The single-seed loop's joint step (Trainer._update) with the given normal draws."""
    with _normal_noise(noise.unbind(0)):
        out = loss(batch.clone())
    total = sum(v for k, v in out.items() if k.startswith("loss_"))
    for optimizer in optimizers:
        optimizer.zero_grad(set_to_none=True)
    total.backward()
    for optimizer in optimizers:
        optimizer.step()
    updater.step()
    return out.detach()


@pytest.mark.parametrize("num_costs", [0, 1])
def test_losses_and_gradients_equal_each_single_loss(num_costs):
    losses = make_losses(num_costs)
    references = [copy.deepcopy(loss) for loss in losses]
    group = stacked_group(losses)
    batches, noise = make_batches(num_costs), make_noise()

    out = group.loss(batches, noise)
    sum(v.sum() for k, v in out.items() if k.startswith("loss_")).backward()
    stacked_grads = {
        k: v.grad for k, v in group.params.flatten_keys().items() if v.grad is not None
    }
    assert stacked_grads  # actor, critics and alpha all receive gradients
    for k, reference in enumerate(references):
        with _normal_noise(noise[k].unbind(0)):
            expected = reference(batches[k].clone())
        sum(v for key, v in expected.items() if key.startswith("loss_")).backward()
        for key in expected.keys():
            torch.testing.assert_close(out[key][k], expected[key].detach(), rtol=1e-5, atol=1e-6)
        reference_leaves = leaves(reference)
        for key, grad in stacked_grads.items():
            torch.testing.assert_close(
                grad[k], reference_leaves[key].grad, rtol=1e-5, atol=1e-6, msg=key
            )
    # Per-agent lambda and alpha were used (not agent 0's for everyone).
    assert out["alpha"].tolist() == pytest.approx([0.005, 0.010, 0.015])
    if num_costs:
        assert out["lagrangian"].squeeze(-1).tolist() == [0.0, 0.5, 1.0]


@pytest.mark.slow  # torch.compile of the vmapped loss: about a minute on a busy 2-core machine
def test_compiled_group_equals_each_eager_single_loss():
    """Compiled (`compile=true` with `seeds`), the vmapped step traces the package's ReLU as
    float ops; losses and gradients are still each eager single loss's."""
    from s3rl_torchrl.trainer.loop import compile_loss

    losses = make_losses(1)
    references = [copy.deepcopy(loss) for loss in losses]
    group = StackedSACLag(losses, LR["actor_lr"], LR["critic_lr"], LR["alpha_lr"], TAU,
                          compile_fn=compile_loss)
    batches, noise = make_batches(1), make_noise()
    out = group.loss(batches, noise)
    sum(v.sum() for k, v in out.items() if k.startswith("loss_")).backward()
    stacked_grads = {k: v.grad for k, v in group.params.flatten_keys().items()
                     if v.grad is not None}
    for k, reference in enumerate(references):
        with _normal_noise(noise[k].unbind(0)):
            expected = reference(batches[k].clone())
        sum(v for key, v in expected.items() if key.startswith("loss_")).backward()
        for key in expected.keys():
            torch.testing.assert_close(out[key][k], expected[key].detach(), rtol=1e-4, atol=1e-5)
        reference_leaves = leaves(reference)
        for key, grad in stacked_grads.items():
            torch.testing.assert_close(
                grad[k], reference_leaves[key].grad, rtol=1e-4, atol=1e-5, msg=key
            )


@pytest.mark.parametrize("fixed_alpha", [False, True])
def test_updates_equal_separate_adams_and_target_updates(fixed_alpha):
    losses = make_losses(1, fixed_alpha=fixed_alpha)
    references = [copy.deepcopy(loss) for loss in losses]
    group = stacked_group(losses)
    singles = []
    for reference in references:
        optimizers = list(make_sac_lag_optimizers(reference, **LR).values())
        singles.append((reference, optimizers, ForeachSoftUpdate(reference, tau=TAU)))
    assert len(group.optimizers) == len(singles[0][1])

    for step in range(3):
        batches, noise = make_batches(1), make_noise(seed=step)
        group.update(batches, noise)
        for k, (reference, optimizers, updater) in enumerate(singles):
            single_step(reference, optimizers, updater, batches[k], noise[k])

    for k, (reference, optimizers, _) in enumerate(singles):
        # Agent k's own loss (views of the stack) holds what its single run holds.
        own, expected = leaves(losses[k]), leaves(reference)
        assert own.keys() == expected.keys()
        for key in expected.keys():
            torch.testing.assert_close(own[key], expected[key], rtol=1e-5, atol=1e-6, msg=key)
        # Its slice of the optimiser states is its single-run optimiser state.
        names = list(make_sac_lag_optimizers(reference, **LR))
        sliced = group.optimizer_state(k)
        assert list(sliced) == names
        for name, optimizer in zip(names, optimizers, strict=True):
            state = optimizer.state_dict()["state"]
            assert sliced[name]["state"].keys() == state.keys()
            for index, entry in state.items():
                for key, value in entry.items():
                    torch.testing.assert_close(
                        sliced[name]["state"][index][key], value, rtol=1e-5, atol=1e-7
                    )


def test_perturbing_one_agents_batch_changes_no_other_agent():
    def after_update(batches):
        losses = make_losses(1)
        group = stacked_group(losses)
        group.update(batches, make_noise())
        return [leaves(loss) for loss in losses]

    batches = make_batches(1)
    perturbed = batches.clone()
    perturbed[1]["next", "reward"] += 10.0
    perturbed[1]["observation"] *= -1
    base, changed = after_update(batches), after_update(perturbed)
    for k in (0, 2):
        for key, value in base[k].items():
            assert torch.equal(value, changed[k][key]), (k, key)
    assert not torch.equal(
        base[1]["qvalue_network_params.module.0.weight"],
        changed[1]["qvalue_network_params.module.0.weight"],
    )


def test_optimizer_states_round_trip():
    group = stacked_group(make_losses(1))
    group.update(make_batches(1), make_noise())
    states = [group.optimizer_state(k) for k in range(K)]
    other = stacked_group(make_losses(1))
    other.load_optimizer_states(states)
    for name, optimizer in group.optimizers.items():
        saved, loaded = optimizer.state_dict()["state"], other.optimizers[name].state_dict()
        for index, entry in saved.items():
            for key, value in entry.items():
                assert torch.equal(loaded["state"][index][key], value)


def test_noise_must_match_the_losses_draws():
    group = stacked_group(make_losses(1))
    noise = make_noise()
    with pytest.raises(RuntimeError, match="more normal samples"):
        group.loss(make_batches(1), noise[:, : NOISE_DRAWS - 1])
    with pytest.raises(RuntimeError, match="shape"):
        group.loss(make_batches(1), noise[:, :, : BATCH - 1])
