"""``algo.contrastive_cfg.label``: validated like every option, wired end to end."""

from __future__ import annotations

import csv
import math

import pytest
import torch
from torchrl.data import Bounded

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.diagnostics import replay_graded_probe
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import GradedInfoNCELoss, SafetyInfoNCELoss
from s3rl_torchrl.trainer import ConfigError, Trainer, builders, train, validate
from s3rl_torchrl.trainer.builders import build_contrastive_phase, build_replay_buffer

COST_TO_GO = ("next", "cost_to_go")


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            ["algo.contrastive_cfg.label=risk"],
            "Invalid value 'risk' for 'algo.contrastive_cfg.label': allowed values are binary, "
            "cost_to_go, margin.",
        ),
        (
            ["algo.contrastive_cfg.positives=nearest"],
            "Invalid value 'nearest' for 'algo.contrastive_cfg.positives': allowed values are "
            "paired, all.",
        ),
        (
            ["algo.contrastive_cfg.label_gamma=1.0"],
            "Invalid value 1.0 for 'algo.contrastive_cfg.label_gamma': must be in [0.0, 1.0).",
        ),
        (
            ["algo.contrastive_cfg.label_bins=[1.0,0.5]"],
            "Invalid value [1.0, 0.5] for 'algo.contrastive_cfg.label_bins': must be null or 1 "
            "to 126 strictly increasing bin edges.",
        ),
        (
            ["task=SafetyCarCircle-v0", "algo.contrastive_cfg.label=margin"],
            "Invalid value 'margin' for 'algo.contrastive_cfg.label': task SafetyCarCircle-v0 "
            "exposes no margin (the goal and velocity tasks do); use binary or cost_to_go.",
        ),
        (
            ["algo=sac_lag", "algo.contrastive_cfg.label=cost_to_go"],
            "Invalid value 'cost_to_go' for 'algo.contrastive_cfg.label': a graded label needs "
            "the contrastive phase (algo.contrastive=true).",
        ),
    ],
)
def test_bad_label_options_fail_in_one_line_before_training(overrides, message, compose):
    with pytest.raises(ConfigError) as err:
        validate(compose("algo=s3rl", *overrides))
    assert str(err.value) == message


def test_binary_stays_the_default(tiny_config):
    cfg = tiny_config("algo=s3rl")
    assert cfg.algo.contrastive_cfg.label == "binary"
    buffer = build_replay_buffer(cfg.algo)
    assert buffer.sampler.label_key == ("next", "safe") and not buffer.sampler.graded


@pytest.mark.parametrize(
    "label, key, edges",
    [("cost_to_go", ("next", "cost_to_go"), (0.05, 1.0, 4.0)),
     ("margin", ("next", "margin"), (0.0, 0.5, 1.0))],
)
def test_graded_label_builds_the_graded_sampler_and_loss(label, key, edges, tiny_config):
    cfg = tiny_config("algo=s3rl", "task=SafetyPointGoal1-v0",
                      f"algo.contrastive_cfg.label={label}")
    buffer = build_replay_buffer(cfg.algo)
    sampler = buffer.sampler
    assert isinstance(sampler, SafeUnsafeSampler)
    assert sampler.label_key == key and sampler.bin_edges == edges
    actor = build_s3rl_actor(4, Bounded(-torch.ones(2), torch.ones(2), shape=(2,)), hidden=(8,))
    phase = build_contrastive_phase(cfg.algo, actor, buffer)
    assert isinstance(phase.loss, GradedInfoNCELoss) and phase.loss.tensor_keys.label == key
    custom = tiny_config("algo=s3rl", f"algo.contrastive_cfg.label={label}",
                         "task=SafetyPointGoal1-v0", "algo.contrastive_cfg.label_bins=[0.3]")
    assert build_replay_buffer(custom.algo).sampler.bin_edges == (0.3,)
    binary = build_contrastive_phase(tiny_config("algo=s3rl").algo, actor, build_replay_buffer(
        tiny_config("algo=s3rl").algo))
    assert type(binary.loss) is SafetyInfoNCELoss


@pytest.mark.parametrize("label", ["cost_to_go", "margin"])
def test_tiny_run_with_a_graded_label_logs_the_graded_probe(label, tiny_config, tmp_path):
    # SafetyPointGoal1 under a random warm-up visits hazards within a few hundred frames, so the
    # graded phase has more than one label bin to contrast.
    cfg = tiny_config("algo=s3rl", "task=SafetyPointGoal1-v0",
                      f"algo.contrastive_cfg.label={label}")
    result = train(cfg, tmp_path / "run")
    assert result.status == "finished"
    assert result.counters.contrastive_phases > 0
    with open(tmp_path / "run" / "metrics.csv") as file:
        rows = list(csv.DictReader(file))
    assert rows and {"probe/spearman", "probe/r2", "probe/accuracy"} <= set(rows[-1])
    last = rows[-1]
    assert not math.isnan(float(last["contrastive/loss_infonce"]))
    spearman, r2 = float(last["probe/spearman"]), float(last["probe/r2"])
    assert -1.0 <= spearman <= 1.0 and r2 <= 1.0


def test_a_group_of_seeds_trains_each_on_its_graded_label(tiny_config, tmp_path):
    # seeds=[...]: each seed stores its own cost-to-go labels (its labeller, its batches) and
    # logs its own graded probe, as a single run does.
    from s3rl_torchrl.trainer import MultiSeedTrainer
    from s3rl_torchrl.trainer.builders import GRADED_LABEL_KEYS

    cfg = tiny_config("algo=s3rl", "task=SafetyPointGoal1-v0",
                      "algo.contrastive_cfg.label=cost_to_go", "seeds=[3,4]")
    group = MultiSeedTrainer(cfg, tmp_path / "group")
    result = group.run()
    assert result.status == "finished"
    key = GRADED_LABEL_KEYS["cost_to_go"]
    stored = []
    for member, run in zip(group.members, result.runs, strict=True):
        assert run.counters.contrastive_phases > 0
        with open(run.run_dir / "metrics.csv") as file:
            last = list(csv.DictReader(file))[-1]
        assert not math.isnan(float(last["contrastive/loss_infonce"]))
        assert -1.0 <= float(last["probe/spearman"]) <= 1.0
        stored.append(member.replay_buffer[:].get(key))
    # Each seed's own episodes, so its own labels.
    assert not torch.equal(stored[0], stored[1])


def _rows(run_dir) -> list[dict]:
    with open(run_dir / "metrics.csv") as file:
        return list(csv.DictReader(file))


@pytest.mark.parametrize("algo", ["s3rl", "sac_lag", "ppo_lag"])
def test_binary_runs_and_baselines_probe_the_cost_to_go(algo, tiny_config, tmp_path):
    # The graded probe runs for every algo, as the binary one does: on the cost-to-go when
    # the run contrasts no graded label. Each stored step carries its label.
    trainer = Trainer(tiny_config(f"algo={algo}", "task=SafetyPointGoal1-v0"), tmp_path / algo)
    assert trainer.run().status == "finished"
    last = _rows(tmp_path / algo)[-1]
    assert -1.0 <= float(last["probe/spearman"]) <= 1.0 and float(last["probe/r2"]) <= 1.0
    stored = trainer.replay_buffer[:]
    cost_to_go, safe = stored.get(COST_TO_GO), stored.get(("next", "safe"))
    # G_t = c_t + gamma_c * G_{t+1} >= c_t >= 0, and c_t > 0 exactly where s_t is unsafe.
    assert (cost_to_go >= 0).all() and (cost_to_go[~safe] > 0).all()
    assert (~safe).any() and (cost_to_go[safe] > 0).any()  # costs ahead of safe steps


def test_what_the_probe_measures_does_not_change_what_is_trained(
    tiny_config, tmp_path, monkeypatch
):
    # Binary S3RL probed on the cost-to-go (labelled before storing) against the same run
    # probed on the margin (no labeller; every step has it): equal training, probe aside.
    overrides = ("algo=s3rl", "task=SafetyPointGoal1-v0")
    train(tiny_config(*overrides), tmp_path / "cost_to_go")
    monkeypatch.setattr(builders, "probe_label", lambda algo: "margin")
    assert builders.build_labeller(tiny_config(*overrides).algo) is None
    train(tiny_config(*overrides), tmp_path / "margin")
    probed, other = _rows(tmp_path / "cost_to_go"), _rows(tmp_path / "margin")
    assert len(probed) == len(other) > 1
    for a, b in zip(probed, other, strict=True):
        assert a["probe/spearman"] != b["probe/spearman"]
        for key in ("probe/spearman", "probe/r2", "eval/seconds"):
            a.pop(key), b.pop(key)
        assert a == b


def test_a_checkpoint_without_the_probed_label_resumes(tiny_config, tmp_path):
    # A checkpoint written before binary runs stored the cost-to-go: its steps get NaN, which
    # the probe skips; the resumed run stores the label from then on.
    overrides = ("algo=s3rl", "task=SafetyPointGoal1-v0")

    def stop_after_first_epoch(trainer: Trainer, row):
        trainer.stop.requested = True

    part = Trainer(tiny_config(*overrides), tmp_path / "part", stop_after_first_epoch)
    part.run()
    part.replay_buffer.storage._storage.del_(COST_TO_GO)
    part.save()
    stored = len(part.replay_buffer)
    cfg = tiny_config(*overrides)
    cfg.resume = str(tmp_path / "part")
    resumed = Trainer(cfg, tmp_path / "ignored")
    labels = resumed.replay_buffer[:].get(COST_TO_GO)
    assert labels.isnan().all() and len(labels) == stored
    assert resumed.run().status == "finished"
    labels = resumed.replay_buffer[:].get(COST_TO_GO)
    assert labels[:stored].isnan().all() and not labels[stored:].isnan().any()
    assert len(labels) > stored
    # The probe samples the labelled steps only (one bin, all of them).
    probe = replay_graded_probe(resumed.replay_buffer, get_policy_encoder(resumed.agent.actor),
                                seed=0, label_key=COST_TO_GO, per_bin=len(labels))
    assert probe.n_train + probe.n_test == len(labels) - stored
