"""The on-policy schedule (PPO family) in the trainer: minibatch passes over each collect,
the buffers it keeps, resume inside a collect, and the losses the registry builds."""

from __future__ import annotations

import pytest
import torch
from torchrl.objectives import ClipPPOLoss

from s3rl_torchrl.objectives import PPOLagLoss
from s3rl_torchrl.trainer import Trainer


def test_each_collect_gets_ppo_epochs_passes_of_minibatches(tiny_config, tmp_path, monkeypatch):
    # tiny: 6 collects of 100 frames, minibatch 32, 4 epochs: per collect 4 passes of
    # minibatches of 32, 32, 32 and 4 transitions, each pass a permutation of the 100.
    cfg = tiny_config("algo=ppo_lag", "diagnostics.probes=true")
    seen = []
    original = Trainer._update

    def record(self, batch):
        seen.append(batch["index"].clone())
        return original(self, batch)

    monkeypatch.setattr(Trainer, "_update", record)
    trainer = Trainer(cfg, tmp_path)
    result = trainer.run()
    frames, epochs, size = cfg.collector.frames_per_batch, cfg.algo.ppo_epochs, cfg.algo.batch_size
    per_epoch = -(-frames // size)
    assert result.counters.grad_steps == len(seen) == 6 * epochs * per_epoch == 96
    assert [len(i) for i in seen[:per_epoch]] == [32, 32, 32, 4]
    passes = [torch.cat(seen[k : k + per_epoch]) for k in range(0, len(seen), per_epoch)]
    for order in passes:
        assert sorted(order.tolist()) == list(range(frames))
    assert not torch.equal(passes[0], passes[1])  # a new permutation each pass
    # The rollout holds the last collect only, with its advantages.
    rollout = trainer.updates.rollout
    assert len(rollout) == frames
    stored = set(rollout[:].keys(True, True))
    assert {"advantage", "value_target", "cost_advantage", "cost_value_target"} <= stored
    # The labelled FIFO keeps the states, their safe/unsafe label and their cost-to-go only
    # (what the contrastive sampler and the two probes read; the probes are on here), every
    # collected frame while it has room.
    labelled = set(trainer.replay_buffer[:].keys(True, True))
    assert labelled == {"observation", ("next", "safe"), ("next", "cost_to_go"), "index"}
    assert len(trainer.replay_buffer) == cfg.collector.total_frames


def test_ppo_collects_with_its_policy_from_the_first_frame(tiny_config, tmp_path):
    # No uniform-random warm-up (tiny asks for 200 frames of it: the off-policy schedule's).
    cfg = tiny_config("algo=ppo")
    trainer = Trainer(cfg, tmp_path)
    assert cfg.collector.init_random_frames == 200
    collector = trainer._make_collector()
    try:
        assert collector.init_random_frames == 0
    finally:
        collector.shutdown()


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo_lag", "s3rl_ppo_lag"])
def test_interrupt_inside_a_collect_resumes_on_the_same_minibatches(
    algo, tiny_config, tmp_path, monkeypatch
):
    # Stopped after step 90 of 96 (inside the last collect's passes): the resumed run takes the
    # 6 remaining minibatches from the saved rollout and its sampler's permutation, without
    # collecting again, so it ends with the uninterrupted run's weights, not only its counters.
    cfg = tiny_config(f"algo={algo}", "task=SafetySwimmerVelocity-v1", "task.cost_limit=0")
    full = Trainer(cfg, tmp_path / "full")
    full_result = full.run()

    original = Trainer._gradient_step

    def stop_at_step_90(self):
        original(self)
        if self.counters.grad_steps == 90:
            self.stop.requested = True

    monkeypatch.setattr(Trainer, "_gradient_step", stop_at_step_90)
    part = Trainer(cfg, tmp_path / "part").run()
    monkeypatch.setattr(Trainer, "_gradient_step", original)
    assert part.status == "interrupted" and part.counters.grad_steps == 90
    assert part.counters.pending_updates == 6

    cfg.resume = str(tmp_path / "part")
    resumed = Trainer(cfg, tmp_path / "ignored")
    result = resumed.run()
    assert vars(result.counters) == vars(full_result.counters)
    ours, theirs = resumed.agent.loss.state_dict(), full.agent.loss.state_dict()
    assert ours.keys() == theirs.keys()
    for key in ours:
        torch.testing.assert_close(ours[key], theirs[key], rtol=0, atol=0)


def test_ppo_is_torchrl_clipppoloss_with_ppo_lag_settings(tiny_config, tmp_path):
    # algo=ppo is torchrl's ClipPPOLoss itself (PPOLagLoss at lambda 0 equals it:
    # tests/objectives/test_ppo_lag.py), with every setting PPO-Lag's loss gets.
    ppo = Trainer(tiny_config("algo=ppo"), tmp_path / "ppo").agent
    lag = Trainer(tiny_config("algo=ppo_lag"), tmp_path / "lag").agent
    assert type(ppo.loss) is ClipPPOLoss and type(lag.loss) is PPOLagLoss
    assert ppo.lagrangian is None and lag.lagrangian is not None
    for name in ("clip_epsilon", "critic_coeff"):
        assert float(getattr(ppo.loss, name)) == float(getattr(lag.loss, name))
    for name in ("entropy_bonus", "normalize_advantage", "loss_critic_type"):
        assert getattr(ppo.loss, name) == getattr(lag.loss, name)
    for name in ("gamma", "lmbda"):
        assert float(getattr(ppo.loss.value_estimator, name)) == float(
            getattr(lag.loss.value_estimator, name)
        )
    assert float(lag.loss.clip_epsilon) == pytest.approx(0.2)
    assert not lag.loss.entropy_bonus and lag.loss.normalize_advantage
    assert float(lag.loss.value_estimator.lmbda) == pytest.approx(0.95)
    assert lag.loss.cost_surrogate == "unclipped" and lag.loss.rescaling
