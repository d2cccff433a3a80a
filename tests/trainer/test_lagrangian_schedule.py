"""The trainer moves lambda as FSRL does (docs/objectives.md, "Lagrangian schedule"): once per
collect, from that collect's mean episode cost, before its gradient steps, which all use it."""

from __future__ import annotations

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
    fed: list[torch.Tensor] = []
    running: list[torch.Tensor] = []  # per-env cost of the episodes still going
    update_lagrangian, update = Trainer._update_lagrangian, Trainer._update

    def record_update_lagrangian(self, batch):
        controller_update = self.agent.lagrangian.update
        self.agent.lagrangian.update = lambda cost: (fed.append(cost), controller_update(cost))[1]
        try:
            update_lagrangian(self, batch)
        finally:
            del self.agent.lagrangian.update
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
            assert torch.allclose(fed[-1].float(), torch.stack(ended).mean(0))
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
