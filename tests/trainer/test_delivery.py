"""The delivered policy (eval.delivery_epochs): the last epochs' policies kept, one picked on
fresh episodes and reported on others; checked by hand and against a run without it."""

from __future__ import annotations

import json

import pytest
import torch

from s3rl_torchrl.trainer import Trainer, loop, train
from s3rl_torchrl.trainer.checkpoint import load_checkpoint
from s3rl_torchrl.trainer.evaluate_checkpoint import load_policy
from s3rl_torchrl.trainer.evaluation import DeliveryCandidates, EvalResult, pick_delivered


def result(reward: float, cost: float) -> EvalResult:
    return EvalResult(reward, 0.0, cost, 0.0, 10.0, 100.0, 1)


def test_pick_is_the_best_reward_within_the_limit_else_the_cheapest():
    # limit 10: candidates 1 (reward 50, cost 4) and 3 (80, 10: at the limit counts) are within;
    # 2 (300, 40) is not, however high its reward.
    assert pick_delivered([result(50, 4), result(300, 40), result(80, 10)], 10.0) == (2, True)
    # A tie on reward goes to the later policy.
    assert pick_delivered([result(80, 1), result(80, 9)], 10.0) == (1, True)
    # None within: the lowest cost (the later on a tie), flagged as not within.
    assert pick_delivered([result(9, 30), result(1, 12), result(5, 12)], 10.0) == (2, False)
    with pytest.raises(ValueError, match="no candidate"):
        pick_delivered([], 10.0)


def test_candidates_keep_the_last_epochs_weights_as_copies():
    policy = torch.nn.Linear(2, 1)
    kept = DeliveryCandidates(2)
    for epoch in (1, 2, 3):
        with torch.no_grad():
            policy.weight.fill_(epoch)
        kept.add(epoch, 100 * epoch, policy)
    copies = list(kept.policies(policy))
    assert [c["epoch"] for c, _ in copies] == [2, 3] and [c["frames"] for c, _ in copies] == [200, 300]
    assert [p.weight[0, 0].item() for _, p in copies] == [2.0, 3.0]
    assert policy.weight[0, 0].item() == 3.0 and all(p is not policy for _, p in copies)
    restored = DeliveryCandidates(2)
    restored.load_state_dict(kept.state_dict())
    assert [p.weight[0, 0].item() for _, p in restored.policies(policy)] == [2.0, 3.0]
    with pytest.raises(ValueError, match="epochs"):
        DeliveryCandidates(0)


def test_a_run_delivers_its_pick_and_keeps_the_last_policy_untouched(tiny_config, tmp_path):
    # The same seeded run without and with the pick: training and the last policy's evaluation
    # are the same; the pick is the rule applied to the candidates' recorded evaluations.
    overrides = ("algo=sac_lag", "collector.total_frames=600", "eval.random_baseline=false",
                 "eval.final_episodes=3")
    plain = train(tiny_config(*overrides), tmp_path / "plain")
    cfg = tiny_config(*overrides, "eval.delivery_epochs=2", "eval.delivery_episodes=2",
                      "eval.delivery_cost_share=0.5")
    picked = train(cfg, tmp_path / "picked")
    first = json.loads((tmp_path / "plain" / "final_eval.json").read_text())
    saved = json.loads((tmp_path / "picked" / "final_eval.json").read_text())
    delivered = saved.pop("delivered")
    assert saved == first and "delivered" not in first
    assert plain.counters.grad_steps == picked.counters.grad_steps
    epochs = picked.history[-1]["epoch"]
    candidates = delivered["candidates"]
    assert [c["epoch"] for c in candidates] == [epochs - 1, epochs]
    assert [c["frames"] for c in candidates] == [row["frames"] for row in picked.history[-2:]]
    limit = 0.5 * cfg.task.cost_limit
    assert delivered["pick_cost_limit"] == limit
    index, within = pick_delivered([result(c["reward"], c["cost"]) for c in candidates], limit)
    assert delivered["epoch"] == candidates[index]["epoch"] and delivered["picked_within"] == within
    assert delivered["episodes"] == 3  # reported on the final episodes, not the picking ones


def test_report_all_reports_every_candidate_after_the_run_s_own_numbers(tiny_config, tmp_path):
    # eval.delivery_report_all: each candidate also on final_episodes other episodes, evaluated
    # after everything the run reports without it, which stays as it was.
    overrides = ("algo=sac_lag", "collector.total_frames=600", "eval.final_episodes=3",
                 "eval.delivery_epochs=2", "eval.delivery_episodes=2")
    train(tiny_config(*overrides), tmp_path / "picked")
    train(tiny_config(*overrides, "eval.delivery_report_all=true"), tmp_path / "all")
    first = json.loads((tmp_path / "picked" / "final_eval.json").read_text())
    saved = json.loads((tmp_path / "all" / "final_eval.json").read_text())
    reports = [(c.pop("report_reward"), c.pop("report_cost")) for c in saved["delivered"]["candidates"]]
    assert saved == first
    assert len(reports) == 2 and all(cost >= 0 for _, cost in reports)
    assert all("report_cost" not in c for c in first["delivered"]["candidates"])


def test_resume_keeps_the_candidates(tiny_config, tmp_path):
    overrides = ("algo=sac_lag", "collector.total_frames=600", "eval.delivery_epochs=3")

    def stop_after_second_epoch(trainer: Trainer, row):
        trainer.stop.requested = row["epoch"] == 2

    part = Trainer(tiny_config(*overrides), tmp_path / "part", stop_after_second_epoch)
    part.run()
    kept = part.delivery.state_dict()["candidates"]
    assert [c["epoch"] for c in kept] == [1, 2]
    resumed = Trainer(tiny_config(*overrides, f"resume={tmp_path / 'part'}"), tmp_path / "x")
    restored = resumed.delivery.state_dict()["candidates"]
    assert [c["epoch"] for c in restored] == [1, 2]
    for a, b in zip(kept, restored, strict=True):
        assert all(torch.equal(a["weights"][k], b["weights"][k]) for k in a["weights"])


def test_the_pick_is_a_checkpoint_s3rl_eval_loads(tiny_config, tmp_path, monkeypatch):
    # checkpoints/delivered holds the picked candidate's actor, as s3rl-eval loads it; the run's
    # own actor is still the last policy afterwards. The older candidate is picked (the rule is
    # tested above), so that the pick's weights are not the last policy's.
    monkeypatch.setattr(loop, "pick_delivered", lambda results, limit: (0, True))
    cfg = tiny_config("algo=sac_lag", "collector.total_frames=600", "eval.random_baseline=false",
                      "eval.final_episodes=2", "eval.delivery_epochs=2",
                      "eval.delivery_episodes=2")
    trainer = Trainer(cfg, tmp_path / "run")
    trainer.run()
    candidates = {c["epoch"]: c["weights"] for c in trainer.delivery.state_dict()["candidates"]}
    first, last = sorted(candidates)
    assert any(not torch.equal(candidates[first][k], candidates[last][k]) for k in candidates[last])
    delivered = json.loads((tmp_path / "run" / "final_eval.json").read_text())["delivered"]
    assert delivered["epoch"] == first
    actor, saved_cfg = load_policy(tmp_path / "run" / "checkpoints" / "delivered")
    assert saved_cfg.eval.delivery_epochs == 2
    weights = actor.state_dict()
    assert all(torch.equal(weights[k], candidates[delivered["epoch"]][k]) for k in weights)
    own = trainer.agent.actor.state_dict()
    assert all(torch.equal(own[k], candidates[last][k]) for k in own)
    state, _ = load_checkpoint(tmp_path / "run" / "checkpoints" / "delivered")
    assert state["delivered"]["epoch"] == delivered["epoch"]
