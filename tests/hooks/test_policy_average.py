"""The actor's weight averages (eval.ema_horizons): the average against the formula by hand,
evaluated beside a run without changing it, kept across a resume."""

from __future__ import annotations

import json

import pandas as pd
import pytest
import torch

from s3rl_torchrl.hooks import PolicyAverage
from s3rl_torchrl.trainer import Trainer, train
from s3rl_torchrl.trainer.evaluation import EvalResult

RUN = ("algo=sac_lag", "collector.total_frames=600", "eval.final_episodes=2")


def never_evaluated(*args) -> EvalResult:
    raise AssertionError("not evaluated in this test")


def test_the_average_is_the_exponential_moving_average_by_hand():
    actor = torch.nn.Linear(1, 1, bias=False)
    hook = PolicyAverage(actor, [4], "SafetyHopperVelocity-v1", 0, 1, 1, None, never_evaluated)
    decay, expected = 1 - 1 / 4, None
    for value in (2.0, 6.0, -1.0, 3.5):
        with torch.no_grad():
            actor.weight.fill_(value)
        hook.update(losses=None)
        # The first update copies the weights; each later one moves 1/h of the way to them.
        expected = value if expected is None else decay * expected + (1 - decay) * value
        assert hook.policy(4).weight.item() == pytest.approx(expected, rel=1e-6)
    # 2, then 0.75 * 2 + 0.25 * 6 = 3, 0.75 * 3 - 0.25 = 2, 0.75 * 2 + 0.25 * 3.5 = 2.375.
    assert hook.policy(4).weight.item() == pytest.approx(2.375, rel=1e-6)
    assert actor.weight.item() == 3.5  # the actor itself is left alone


def test_the_average_is_torchs_averaged_model():
    # The same exponential moving average as torch.optim.swa_utils.AveragedModel's, weight for
    # weight, over a small network's changing weights.
    from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

    from s3rl_torchrl.hooks.policy_average import WeightAverage

    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.Tanh(), torch.nn.Linear(4, 2))
    ours = WeightAverage(net, 0.9)
    reference = AveragedModel(net, multi_avg_fn=get_ema_multi_avg_fn(0.9))
    for _ in range(5):
        with torch.no_grad():
            for p in net.parameters():
                p.add_(torch.randn_like(p))
        ours.update(net)
        reference.update_parameters(net)
    for mine, theirs in zip(ours.module.parameters(), reference.module.parameters(), strict=True):
        assert torch.allclose(mine, theirs, rtol=0, atol=1e-6)
    # Checkpoints keep it, and take back what an AveragedModel kept (the hook's first form).
    for saved in (ours.state_dict(), reference.state_dict()):
        restored = WeightAverage(net, 0.9)
        restored.load_state_dict(saved)
        assert restored.updates == 5
        for a, b in zip(restored.module.parameters(), ours.module.parameters(), strict=True):
            assert torch.allclose(a, b, rtol=0, atol=1e-6)


def test_horizons_are_checked():
    actor = torch.nn.Linear(1, 1)
    for horizons in ([], [0], [5, 5]):
        with pytest.raises(ValueError, match="horizons"):
            PolicyAverage(actor, horizons, "SafetyHopperVelocity-v1", 0, 1, 1, None,
                          never_evaluated)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("eval.ema_horizons=[0]", r"eval.ema_horizons.*must be in \[1, inf\)"),
        ("eval.ema_horizons=[10,10]", "eval.ema_horizons.*must not repeat a horizon"),
        ("seeds=[1,2]", "eval.ema_horizons.*single-seed runs"),
    ],
)
def test_bad_horizons_are_refused_before_training(tiny_config, override, message):
    overrides = ["eval.ema_horizons=[10]", override] if override.startswith("seeds") else [override]
    with pytest.raises(ValueError, match=message):
        tiny_config(*overrides)


def test_averages_are_evaluated_beside_an_unchanged_run(tiny_config, tmp_path):
    plain = train(tiny_config(*RUN), tmp_path / "plain")
    trainer = Trainer(tiny_config(*RUN, "eval.ema_horizons=[1,50]"), tmp_path / "averaged")
    averaged = trainer.run()
    # Training, the policy's own evaluations and its final one are those of the plain run.
    assert plain.counters.grad_steps == averaged.counters.grad_steps
    for row_plain, row in zip(plain.history, averaged.history, strict=True):
        assert {k: row[k] for k in ("eval/reward", "eval/cost", "lagrangian")} == {
            k: row_plain[k] for k in ("eval/reward", "eval/cost", "lagrangian")
        }
    first = json.loads((tmp_path / "plain" / "final_eval.json").read_text())
    saved = json.loads((tmp_path / "averaged" / "final_eval.json").read_text())
    assert {k: v for k, v in saved.items() if not k.startswith("ema")} == first
    assert saved["ema1"]["episodes"] == saved["ema50"]["episodes"] == 2
    metrics = pd.read_csv(tmp_path / "averaged" / "metrics.csv")
    for name in ("ema1", "ema50"):
        assert metrics[f"{name}/cost"].notna().all() and metrics[f"{name}/length"].gt(0).all()
    # Horizon 1 (decay 0) is the last weights themselves; 50 steps lag behind them.
    hook = trainer._hooks["policy_average"]
    own = trainer.agent.actor.state_dict()
    last = hook.policy(1).state_dict()
    slow = hook.policy(50).state_dict()
    assert all(torch.equal(own[k], last[k]) for k in own)
    assert any(not torch.equal(own[k], slow[k]) for k in own)


def test_resume_continues_the_averages_exactly(tiny_config, tmp_path):
    overrides = (*RUN, "eval.ema_horizons=[20]")
    whole = Trainer(tiny_config(*overrides), tmp_path / "whole")
    whole.run()

    def stop_after_second_epoch(trainer: Trainer, row):
        trainer.stop.requested = row["epoch"] == 2

    Trainer(tiny_config(*overrides), tmp_path / "part", stop_after_second_epoch).run()
    resumed = Trainer(tiny_config(*overrides, f"resume={tmp_path / 'part'}"), tmp_path / "x")
    resumed.run()
    a = whole._hooks["policy_average"].policy(20).state_dict()
    b = resumed._hooks["policy_average"].policy(20).state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    columns = ["ema20/reward", "ema20/cost"]
    assert pd.read_csv(tmp_path / "part" / "metrics.csv")[columns].equals(
        pd.read_csv(tmp_path / "whole" / "metrics.csv")[columns]
    )
