"""Graded labels (hooks/labels.py): ``algo.contrastive_cfg.label`` validated like every
option and wired end to end; the label stored only for the runs that contrast or probe one, and
given to old buffers without it."""

from __future__ import annotations

import csv
import math

import pytest
import torch
from torchrl.data import Bounded

from s3rl_torchrl.algorithms.contrastive import LABEL_KEYS, build_contrastive_phase
from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.diagnostics import replay_graded_probe
from s3rl_torchrl.hooks import GradedLabels
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import GradedInfoNCELoss, SafetyInfoNCELoss
from s3rl_torchrl.trainer import ConfigError, Trainer, train, validate
from s3rl_torchrl.trainer.builders import build_replay_buffer

COST_TO_GO = ("next", "cost_to_go")
PROBES = "diagnostics.probes=true"


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
    phase = build_contrastive_phase(cfg.algo.contrastive_cfg, actor, buffer)
    assert isinstance(phase.loss, GradedInfoNCELoss) and phase.loss.tensor_keys.label == key
    custom = tiny_config("algo=s3rl", f"algo.contrastive_cfg.label={label}",
                         "task=SafetyPointGoal1-v0", "algo.contrastive_cfg.label_bins=[0.3]")
    assert build_replay_buffer(custom.algo).sampler.bin_edges == (0.3,)
    binary_algo = tiny_config("algo=s3rl").algo
    binary = build_contrastive_phase(
        binary_algo.contrastive_cfg, actor, build_replay_buffer(binary_algo)
    )
    assert type(binary.loss) is SafetyInfoNCELoss


@pytest.mark.parametrize("label", ["cost_to_go", "margin"])
def test_tiny_run_with_a_graded_label_logs_the_graded_probe(label, tiny_config, tmp_path):
    # SafetyPointGoal1 under a random warm-up visits hazards within a few hundred frames, so the
    # graded phase has more than one label bin to contrast.
    cfg = tiny_config("algo=s3rl", "task=SafetyPointGoal1-v0",
                      f"algo.contrastive_cfg.label={label}", PROBES)
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

    cfg = tiny_config("algo=s3rl", "task=SafetyPointGoal1-v0",
                      "algo.contrastive_cfg.label=cost_to_go", "seeds=[3,4]", PROBES)
    group = MultiSeedTrainer(cfg, tmp_path / "group")
    result = group.run()
    assert result.status == "finished"
    key = LABEL_KEYS["cost_to_go"]
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
    # With the probes on, the graded probe runs for every algo, as the binary one does: on the
    # cost-to-go when the run contrasts no graded label. Each stored step carries its label.
    cfg = tiny_config(f"algo={algo}", "task=SafetyPointGoal1-v0", PROBES)
    trainer = Trainer(cfg, tmp_path / algo)
    assert trainer.run().status == "finished"
    last = _rows(tmp_path / algo)[-1]
    assert -1.0 <= float(last["probe/spearman"]) <= 1.0 and float(last["probe/r2"]) <= 1.0
    stored = trainer.replay_buffer[:]
    cost_to_go, safe = stored.get(COST_TO_GO), stored.get(("next", "safe"))
    # G_t = c_t + gamma_c * G_{t+1} >= c_t >= 0, and c_t > 0 exactly where s_t is unsafe.
    assert (cost_to_go >= 0).all() and (cost_to_go[~safe] > 0).all()
    assert (~safe).any() and (cost_to_go[safe] > 0).any()  # costs ahead of safe steps


@pytest.mark.parametrize("algo", ["s3rl", "ppo_lag"])
def test_the_probes_and_their_label_change_nothing_that_is_trained(algo, tiny_config, tmp_path):
    # A run that does not ask for the probes stores no graded label and logs no probe column;
    # everything else of its metrics is the probed run's.
    overrides = (f"algo={algo}", "task=SafetyPointGoal1-v0")
    # One after the other: building a trainer seeds the global random streams.
    probed = Trainer(tiny_config(*overrides, PROBES), tmp_path / "probed")
    assert probed.run().status == "finished"
    plain = Trainer(tiny_config(*overrides), tmp_path / "plain")
    assert plain.run().status == "finished"
    assert COST_TO_GO in probed.replay_buffer[:].keys(True)
    assert COST_TO_GO not in plain.replay_buffer[:].keys(True)
    rows_probed, rows_plain = _rows(tmp_path / "probed"), _rows(tmp_path / "plain")
    assert len(rows_probed) == len(rows_plain) > 1
    for a, b in zip(rows_probed, rows_plain, strict=True):
        probe_columns = {key for key in a if key.startswith("probe/")}
        assert probe_columns == {"probe/accuracy", "probe/auc", "probe/spearman", "probe/r2"}
        assert not probe_columns & set(b)
        for key in (*probe_columns, "eval/seconds"):
            a.pop(key)
        b.pop("eval/seconds")
        assert a == b


def test_a_buffer_without_the_label_gets_nan_labels(tiny_config):
    # A checkpoint written before every run stored a graded label (before commit 00fa9dd) is
    # resumed with the label (its config has no `diagnostics`: the probes stay on). Its stored
    # steps get NaN, which the probe skips; new steps carry the label; nothing else changes.
    from tensordict import TensorDict

    cfg = tiny_config("algo=sac_lag", PROBES)
    buffer = build_replay_buffer(cfg.algo)
    g = torch.Generator().manual_seed(0)
    old = TensorDict(
        {"observation": torch.randn(20, 3, generator=g),
         ("next", "safe"): torch.rand(20, 1, generator=g) < 0.5},
        [20],
    )
    buffer.extend(old)
    labels = GradedLabels.for_run(cfg.algo, cfg.diagnostics.probes)
    labels.register(_Host(buffer), "labels")
    labels.load_state_dict({})
    stored = buffer[:]
    assert len(buffer) == 20 and stored.get(COST_TO_GO).isnan().all()
    assert torch.equal(stored["observation"], old["observation"])
    assert torch.equal(stored["next", "safe"], old["next", "safe"])
    new = old.clone().set(COST_TO_GO, torch.rand(20, 1, generator=g) * 5)
    buffer.extend(new)
    assert len(buffer) == 40 and torch.equal(buffer[:][COST_TO_GO][20:], new[COST_TO_GO])
    # A buffer that has the label keeps it.
    labels.load_state_dict({})
    assert torch.equal(buffer[:][COST_TO_GO][20:], new[COST_TO_GO])
    # The probe samples the labelled steps only (one bin, all of them).
    encoder = get_policy_encoder(build_s3rl_actor(3, Bounded(-torch.ones(2), torch.ones(2)), (4,)))
    probe = replay_graded_probe(buffer, encoder, seed=0, label_key=COST_TO_GO, per_bin=40)
    assert probe.n_train + probe.n_test == 20


class _Host:
    """What a hook registers with, recording it."""

    def __init__(self, replay_buffer):
        self.replay_buffer = replay_buffer
        self.ops, self.modules = [], {}

    def register_op(self, point, op):
        self.ops.append((point, op))

    def register_module(self, name, module):
        self.modules[name] = module


def test_a_resume_cannot_switch_the_stored_label(tiny_config, tmp_path):
    # The buffer and the n-step transform's held frames were written with the run's labels.
    from s3rl_torchrl.trainer import CheckpointError
    from s3rl_torchrl.trainer.resume import resume_config

    def stop_after_first_epoch(trainer: Trainer, row):
        trainer.stop.requested = True

    Trainer(tiny_config("algo=s3rl"), tmp_path, stop_after_first_epoch).run()
    for change in (PROBES, "algo.contrastive_cfg.label=cost_to_go"):
        with pytest.raises(CheckpointError, match=change.split("=")[0]):
            resume_config(tmp_path, [change], echo=False)


def test_which_label_a_run_stores(tiny_config):
    def labels(*overrides):
        cfg = tiny_config(*overrides)
        return GradedLabels.for_run(cfg.algo, cfg.diagnostics.probes)

    assert labels("algo=s3rl") is None and labels("algo=sac") is None
    contrasted = labels("algo=s3rl", "task=SafetyPointGoal1-v0", "algo.contrastive_cfg.label=margin")
    assert (contrasted.label, contrasted.key, contrasted.reads_margin) == (
        "margin", ("next", "margin"), True,
    )
    probed = labels("algo=sac_lag", PROBES, "algo.contrastive_cfg.label_bins=[0.5]")
    assert (probed.label, probed.bins, probed.reads_margin) == ("cost_to_go", (0.5,), False)
    # The contrasted label is also the probed one.
    both = labels("algo=s3rl", "task=SafetyPointGoal1-v0", "algo.contrastive_cfg.label=margin",
                  PROBES)
    assert both.label == "margin"
