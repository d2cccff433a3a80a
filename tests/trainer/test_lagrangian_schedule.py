"""The trainer moves lambda as FSRL does (docs/objectives.md, "Lagrangian schedule"): once per
collect, from that collect's mean episode cost, before its gradient steps, which all use it."""

from __future__ import annotations

import math

import pytest
import torch

from s3rl_torchrl.trainer import Trainer, train


def events_updates(events):
    return [e for e in events if e[0] == "update"]


def test_lambda_moves_once_per_collect_before_its_gradient_steps(
    tiny_config, tmp_path, monkeypatch
):
    # Hopper falls within ~20 random steps, so every 100-frame batch ends episodes; a zero cost
    # limit makes the PID output positive and moving.
    cfg = tiny_config("algo=sac_lag", "task=SafetyHopperVelocity-v0", "task.cost_limit=0")
    events: list[tuple[str, int, torch.Tensor]] = []
    fed: list[list[float]] = []
    running: list[torch.Tensor] = []  # per-env cost of the episodes still going
    update_lagrangian, update = Trainer._update_lagrangian, Trainer._update

    def record_update_lagrangian(self, batch):
        controller = self.agent.lagrangian.controller
        controller_update = controller.update_floats
        controller.update_floats = lambda cost: (fed.append(cost), controller_update(cost))[1]
        try:
            update_lagrangian(self, batch)
        finally:
            del controller.update_floats
        # FSRL's J, recomputed from the per-step costs: every step's cost summed per episode
        # (episodes may straddle batches), averaged over the episodes that ended in this batch.
        cost, done = batch["next", "cost"], batch["next", "done"].squeeze(-1)  # [envs, T, m]
        if running:
            total = running.pop()
        else:
            total = torch.zeros(cost.shape[0], cost.shape[-1])
        ended = []
        for t in range(cost.shape[1]):
            total += cost[:, t]
            for env in torch.nonzero(done[:, t]).flatten().tolist():
                ended.append(total[env].clone())
                total[env] = 0
        running.append(total)
        if ended:
            assert torch.allclose(torch.tensor(fed[-1]).float(), torch.stack(ended).mean(0))
            events.append(("update", self.counters.frames, self.agent.loss.lagrangian.clone()))
        else:
            assert len(fed) == len(events_updates(events))  # no episode ended: no update

    def record_gradient_step(self, batch):
        events.append(("step", self.counters.frames, self.agent.loss.lagrangian.clone()))
        return update(self, batch)

    monkeypatch.setattr(Trainer, "_update_lagrangian", record_update_lagrangian)
    monkeypatch.setattr(Trainer, "_update", record_gradient_step)
    train(cfg, tmp_path)

    c = cfg.collector
    batch_ends = list(range(c.frames_per_batch, c.total_frames + 1, c.frames_per_batch))
    updates = events_updates(events)
    assert [frames for _, frames, _ in updates] == batch_ends  # one per collect
    steps_per_batch = int(cfg.algo.update_per_step * c.frames_per_batch)  # 0.25 x 100
    for i, (_, frames, lam) in enumerate(updates):
        start = events.index(updates[i])
        end = events.index(updates[i + 1]) if i + 1 < len(updates) else len(events)
        steps = events[start + 1 : end]
        # This collect's gradient steps come after its update and all use its lambda.
        owed = steps_per_batch if frames >= c.init_random_frames else 0
        assert len(steps) == owed
        assert all(f == frames and torch.equal(step_lam, lam) for _, f, step_lam in steps)
    lams = torch.stack([lam for _, _, lam in updates]).squeeze(-1)
    assert len(set(lams.tolist())) >= 4 and lams.max() > 1  # it did move, by the cost


def test_step_cadence_updates_after_every_gradient_step_from_the_window(
    tiny_config, tmp_path, monkeypatch
):
    # OmniSafe's cadence: after the warm-up, one Adam step on lambda after every gradient step,
    # from the mean cost of the last `window` finished episodes (a running window across
    # batches). Checked against an independent replay: the per-episode costs recomputed from the
    # per-step costs, a deque of the last 3, and Adam's update written out by hand.
    window, lr, warmup = 3, 0.01, 300
    cfg = tiny_config(
        "algo=sac_lag",
        "task=SafetyHopperVelocity-v0",
        "task.cost_limit=0.5",
        "algo.lagrangian=learned",
        "algo.lagrangian_cadence=step",
        f"algo.lagrangian_window={window}",
        f"algo.lagrangian_lr={lr}",
        "algo.lagrangian_init=0.2",
        f"algo.lagrangian_warmup_frames={warmup}",
    )
    steps: list[tuple[int, float]] = []  # (frames, lambda the gradient step used)
    episodes: list[float] = []  # finished episodes' costs, in the order the trainer saw them
    running: list[torch.Tensor] = []
    update_lagrangian, update = Trainer._update_lagrangian, Trainer._update

    def record_update_lagrangian(self, batch):
        cost, done = batch["next", "cost"], batch["next", "done"].squeeze(-1)  # [envs, T, 1]
        total = running.pop() if running else torch.zeros(cost.shape[0])
        ended = [[] for _ in range(cost.shape[0])]
        for t in range(cost.shape[1]):
            total += cost[:, t, 0]
            for env in torch.nonzero(done[:, t]).flatten().tolist():
                ended[env].append(float(total[env]))
                total[env] = 0
        running.append(total)
        # The window takes the batch's episodes env by env (the order of batch[done]).
        episodes.extend(c for per_env in ended for c in per_env)
        update_lagrangian(self, batch)

    def record_gradient_step(self, batch):
        steps.append((self.counters.frames, float(self.agent.loss.lagrangian)))
        return update(self, batch)

    monkeypatch.setattr(Trainer, "_update_lagrangian", record_update_lagrangian)
    monkeypatch.setattr(Trainer, "_update", record_gradient_step)
    trainer = Trainer(cfg, tmp_path)
    frames_seen: dict[int, int] = {}  # frames -> finished episodes known by then
    observe = trainer.agent.lagrangian.observe

    def record_observe(costs, frames):
        frames_seen[frames] = len(episodes)
        return observe(costs, frames)

    trainer.agent.lagrangian.observe = record_observe
    result = trainer.run()

    # Replay: lambda before the first step after the warm-up is the initial one; after each
    # gradient step past the warm-up, one Adam step from the window's mean.
    lam, m, v, t = 0.2, 0.0, 0.0, 0
    expected = []
    for frames, _ in steps:
        expected.append(lam)
        known = episodes[: frames_seen[frames]]
        if frames > warmup and known:
            j = sum(known[-window:]) / len(known[-window:])
            g = 0.5 - j
            t += 1
            m, v = 0.9 * m + 0.1 * g, 0.999 * v + 0.001 * g * g
            lam = max(0.0, lam - lr * (m / (1 - 0.9**t)) / (math.sqrt(v / (1 - 0.999**t)) + 1e-8))
    assert [s[1] for s in steps] == pytest.approx(expected, abs=1e-6)
    assert result.counters.lagrangian_updates == t > 0
    assert any(frames <= warmup for frames, _ in steps)  # the warm-up held lambda at its init
    assert len({round(x, 6) for x in expected}) > 10  # lambda moved, step by step


def test_resume_keeps_the_window_and_the_warmup_clock(tiny_config, tmp_path):
    # Stopped after the first epoch, mid-window (a window of 50 episodes, ~10 ended so far)
    # and before the warm-up ends: the resumed run starts from the same window, controller
    # state and frame count, and makes as many lambda updates and gradient steps as an
    # uninterrupted run (episodes differ: the env copies restart theirs on resume).
    overrides = (
        "algo=sac_lag",
        "task=SafetyHopperVelocity-v0",
        "task.cost_limit=0.5",
        "algo.lagrangian=learned",
        "algo.lagrangian_cadence=step",
        "algo.lagrangian_window=50",
        "algo.lagrangian_lr=0.01",
        "algo.lagrangian_warmup_frames=300",
    )
    full = train(tiny_config(*overrides), tmp_path / "full")

    def stop_after_first_epoch(trainer: Trainer, row):
        trainer.stop.requested = True

    part = Trainer(tiny_config(*overrides), tmp_path / "part", stop_after_first_epoch)
    part.run()
    updater = part.agent.lagrangian
    assert 0 < len(updater.window) < 50 and updater.warming_up
    cfg = tiny_config(*overrides)
    cfg.resume = str(tmp_path / "part")
    resumed = Trainer(cfg, tmp_path / "ignored")
    restored = resumed.agent.lagrangian
    assert list(restored.window._costs) == list(updater.window._costs)
    assert restored.controller.state_dict() == updater.controller.state_dict()
    assert restored.warming_up and restored._frames == updater._frames == 200
    assert torch.equal(resumed.agent.loss.lagrangian, part.agent.loss.lagrangian)
    result = resumed.run()
    assert result.counters.lagrangian_updates == full.counters.lagrangian_updates > 0
    assert result.counters.grad_steps == full.counters.grad_steps


def test_aimed_controller_holds_a_share_of_the_limit_and_reads_the_evaluations(
    tiny_config, tmp_path, monkeypatch
):
    # algo.lagrangian_target scales the controller's d; algo.lagrangian_eval_window feeds it the
    # per-episode costs of each epoch's deterministic evaluation (not the final one), which a
    # resume carries on from the checkpoint.
    import s3rl_torchrl.trainer.loop as loop

    overrides = (
        "algo=sac_lag",
        "task=SafetyHopperVelocity-v0",
        "task.cost_limit=2",
        "algo.lagrangian=learned",
        "algo.lagrangian_cadence=step",
        "algo.lagrangian_target=0.25",
        "algo.lagrangian_eval_window=3",
        "eval.episodes=2",
    )
    evaluated: list[list[float]] = []
    evaluate = loop.evaluate

    def record(env, policy, episodes, max_steps):
        result = evaluate(env, policy, episodes, max_steps)
        evaluated.append(list(result.episode_costs))
        return result

    monkeypatch.setattr(loop, "evaluate", record)
    trainer = Trainer(tiny_config(*overrides), tmp_path)
    assert trainer.agent.lagrangian.controller.cost_limit.tolist() == [0.5]
    epochs = []
    trainer.register_op("epoch_end", lambda t, row: epochs.append(len(evaluated)))
    trainer.run()
    per_epoch = [costs for i, costs in enumerate(evaluated) if i + 1 in epochs]
    assert len(per_epoch) >= 2 and all(len(costs) == 2 for costs in per_epoch)
    window = trainer.agent.lagrangian.evaluation_window
    assert [row[0] for row in window._costs] == [c for costs in per_epoch for c in costs][-3:]
    restored = loop.Trainer(
        tiny_config(*overrides, f"resume={tmp_path}"), tmp_path / "ignored"
    ).agent.lagrangian
    assert list(restored.evaluation_window._costs) == list(window._costs)
