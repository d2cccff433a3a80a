"""The loops of docs/objectives.md and docs/representation.md run as written, with smaller
numbers."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.transforms import make_nstep_transform

DOC = Path(__file__).resolve().parents[2] / "docs" / "objectives.md"


def run_example(doc: Path, heading: str, shrink: list[tuple[str, str]]) -> dict:
    """Runs the first python block after ``heading`` in ``doc``, with each (as written, smaller)
    replacement of ``shrink`` made, and returns the names it defined. A replacement whose text is
    no longer in the block fails the test: the docs changed, so the shrink list must too."""
    section = doc.read_text().split(heading, 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    for written, small in shrink:
        assert written in code, f"the docs example no longer contains {written!r}"
        code = code.replace(written, small)
    torch.manual_seed(0)
    namespace: dict = {}
    exec(compile(code, str(doc), "exec"), namespace)
    return namespace


# (as written in the docs, what the test runs instead): a few hundred frames, seconds.
SHRINK = [
    ("num_envs=10", "num_envs=2"),
    ("frames_per_batch=2000", "frames_per_batch=100"),
    ("total_frames=1_000_000", "total_frames=300"),
    ("LazyTensorStorage(100_000)", "LazyTensorStorage(1_000)"),
    ("batch_size=256", "batch_size=16"),
]


def test_own_loop_example_runs():
    namespace = run_example(DOC, "## In your own TorchRL loop", SHRINK)
    loss, metrics = namespace["loss"], namespace["metrics"]
    # It trained: gradient steps ran and moved the targets off their initial copy.
    assert set(metrics.keys()) >= {"loss_actor", "loss_qvalue", "loss_cost_qvalue", "lagrangian"}
    assert all(torch.isfinite(v).all() for v in metrics.values())
    online = loss.qvalue_network_params.flatten_keys()
    target = loss.target_qvalue_network_params.flatten_keys()
    assert any(not torch.equal(online[k], target[k]) for k in online.keys())


# The DDPG-Lag / PPO-Lag loops of docs/objectives.md, with smaller numbers.
BASELINES_SHRINK = [
    ("num_envs=10", "num_envs=2"),
    ("frames_per_batch=2000", "frames_per_batch=100"),
    ("total_frames=1_000_000", "total_frames=200"),
    ("LazyTensorStorage(100_000)", "LazyTensorStorage(1_000)"),
    ("batch_size=256", "batch_size=16"),
    ("// 256", "// 16"),
]


def test_ddpg_lag_and_ppo_lag_loop_example_runs():
    namespace = run_example(
        DOC, "### DDPG-Lag and PPO-Lag in your own TorchRL loop", BASELINES_SHRINK
    )
    ddpg_loss, metrics = namespace["loss"], namespace["metrics"]
    assert {"loss_actor", "loss_value", "loss_cost_value", "lagrangian"} <= set(metrics.keys())
    assert all(torch.isfinite(v).all() for v in metrics.values())
    online = ddpg_loss.cost_value_network_params.flatten_keys()
    target = ddpg_loss.target_cost_value_network_params.flatten_keys()
    assert any(not torch.equal(online[k], target[k]) for k in online.keys())
    out = namespace["out"]
    for key in ("loss_objective", "loss_critic", "loss_cost_critic"):
        assert torch.isfinite(out[key])
    # PPO-Lag took Adam steps on every parameter group (actor, value, cost value).
    ppo_loss, optimizer = namespace["ppo_loss"], namespace["optimizer"]
    for params in (
        ppo_loss.actor_network_params,
        ppo_loss.critic_network_params,
        ppo_loss.cost_critic_network_params,
    ):
        for p in params.values(True, True):
            if p.requires_grad:
                assert optimizer.state[p]["step"] > 0


REPRESENTATION_DOC = DOC.parent / "representation.md"
ANY_ACTOR_SHRINK = [
    ("num_envs=4", "num_envs=2"),
    ("frames_per_batch=2000", "frames_per_batch=100"),
    ("total_frames=100_000", "total_frames=300"),
    ("LazyTensorStorage(100_000)", "LazyTensorStorage(1_000)"),
    ("batch_size=256", "batch_size=16"),
    ("contrastive_view(rb, 256)", "contrastive_view(rb, 8)"),
    ("num_steps=50", "num_steps=3"),
    ("grad_steps % 1000", "grad_steps % 10"),
]


def test_contrastive_phase_on_ddpg_lag_example_runs():
    """docs/representation.md, "Any actor": the S3RL encoder phase wired into DDPG-Lag."""
    namespace = run_example(REPRESENTATION_DOC, "### Any actor", ANY_ACTOR_SHRINK)
    phase, metrics = namespace["phase"], namespace["metrics"]
    # The loop called the phase (it runs or skips depending on the safe/unsafe counts; that it
    # trains the DDPG actor's encoder is tested in tests/objectives/test_ddpg_lag.py).
    assert phase.num_runs + phase.num_skipped == namespace["grad_steps"] // 10 > 0
    # The phase owns the DDPG actor's own trunk parameters, not a copy.
    actor_ids = {id(p) for p in namespace["actor"].parameters()}
    assert {id(p) for p in phase.loss.encoder_parameters()} <= actor_ids
    assert all(torch.isfinite(v).all() for v in metrics.values())


# docs/representation.md, "One storage, RL batches and contrastive batches", with smaller numbers.
ONE_STORAGE_SHRINK = [
    ("num_envs=4", "num_envs=2"),
    ("LazyTensorStorage(100_000)", "LazyTensorStorage(1_000)"),
    ("batch_size=256", "batch_size=16"),
    ("contrastive_view(rb, 256)", "contrastive_view(rb, 8)"),
    ("num_steps=50", "num_steps=3"),
    ("frames_per_batch=2000", "frames_per_batch=100"),
    ("total_frames=100_000", "total_frames=300"),
    ("grad_steps % 1000", "grad_steps % 10"),
]


def test_one_storage_example_runs():
    """The page's first loop runs as written: an n-step buffer extended with the collector's
    unflattened batches, RL batches and contrastive phases from one storage."""
    namespace = run_example(REPRESENTATION_DOC, "## One storage, RL batches", ONE_STORAGE_SHRINK)
    rb, phase, grad_steps = namespace["rb"], namespace["phase"], namespace["grad_steps"]
    # 300 frames on 2 env copies: the 2-step transform builds each copy's windows along its 150
    # steps and holds back its last 2 frames, so 2 x 148 transitions are stored (a flattened
    # batch would be one 300-step trajectory: 298).
    assert len(rb) == 2 * (150 - 2)
    stored = rb.storage[: len(rb)]
    # Every window lies within one env copy: its next observation is steps_to_next_obs steps
    # later in the same episode (HalfCheetah never terminates; 150 steps do not truncate).
    assert torch.equal(
        stored["next", "step_count"].squeeze(-1) - stored["step_count"].squeeze(-1),
        stored["steps_to_next_obs"],
    )
    assert (stored["steps_to_next_obs"] == 2).all()
    # The batch is RL-sized, and the phase was called every 10 gradient steps. HalfCheetah under
    # a young policy has no unsafe step, so each call skipped (docs: "When the contrastive
    # phase runs").
    assert namespace["batch"].shape == (16,)
    assert not bool((~stored["next", "safe"]).any())
    assert (phase.num_runs, phase.num_skipped) == (0, grad_steps // 10) and grad_steps == 60
    # The advice beside the loop: the same buffer refuses a flattened batch.
    flat_rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(1_000), sampler=SafeUnsafeSampler(),
        transform=make_nstep_transform(2, 0.99),
    )
    with pytest.raises(ValueError, match="unflattened"):
        flat_rb.extend(namespace["data"].reshape(-1))
