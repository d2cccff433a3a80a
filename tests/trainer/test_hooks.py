"""The trainer's hook points (hooks/base.py): what each op gets, what the trainer does with what
it returns, and a hook's state through a checkpoint."""

from __future__ import annotations

import csv

import pytest
import torch

from s3rl_torchrl.hooks import HOOK_POINTS, TrainerHook
from s3rl_torchrl.trainer import Trainer, train


class Recorder(TrainerHook):
    """Registers at every point; zeroes the collected rewards; counts gradient steps (its
    state)."""

    def __init__(self):
        self.calls: list[str] = []
        self.batches, self.steps, self.rows = [], 0, []

    def register(self, host, name):
        host.register_op("after_collect", self.collected)
        host.register_op("after_update", self.updated)
        host.register_op("after_evaluation", self.evaluated)
        host.register_op("epoch_end", self.ended)
        host.register_module(name, self)

    def collected(self, batch):
        self.calls.append("after_collect")
        self.batches.append(batch.shape)
        batch = batch.clone()
        batch["next", "reward"].zero_()
        return batch

    def updated(self, losses):
        self.calls.append("after_update")
        losses = [value for key, value in losses.items() if key.startswith("loss_")]
        assert losses and not any(value.requires_grad for value in losses)  # detached
        self.steps += 1

    def evaluated(self, row):
        self.calls.append("after_evaluation")
        return {"recorder/steps": float(self.steps), "recorder/epoch": float(row["epoch"])}

    def ended(self, trainer, row):
        self.calls.append("epoch_end")
        self.rows.append(dict(row))

    def state_dict(self):
        return {"steps": self.steps}

    def load_state_dict(self, state):
        self.steps = state.get("steps", 0)


def test_every_point_is_called_with_what_it_documents(tiny_config, tmp_path):
    recorder = Recorder()
    cfg = tiny_config("algo=sac_lag", "collector.total_frames=400")
    trainer = Trainer(cfg, tmp_path, hooks={"recorder": recorder})
    result = trainer.run()
    # One after_collect per collected [envs, time] batch, one after_update per gradient step.
    assert recorder.batches == [torch.Size([2, 50])] * 4
    assert recorder.steps == result.counters.grad_steps == recorder.calls.count("after_update")
    # The batch an after_collect op returns is the one stored: every stored reward is 0.
    assert (trainer.replay_buffer[:]["next", "reward"] == 0).all()
    # after_evaluation's columns are in the epoch's row, metrics.csv and epoch_end's row.
    with open(tmp_path / "metrics.csv") as file:
        rows = list(csv.DictReader(file))
    assert [float(r["recorder/epoch"]) for r in rows] == [1.0, 2.0]
    assert [r["recorder/steps"] for r in recorder.rows] == [25.0, 75.0]
    assert [r["grad_steps"] for r in recorder.rows] == [25, 75]  # 0.25 per frame from 200
    # Within an epoch: collects and steps, then the evaluation's columns, then its end.
    first_end = recorder.calls.index("epoch_end")
    assert recorder.calls[first_end - 1] == "after_evaluation"


def test_a_hooks_state_is_in_the_checkpoint(tiny_config, tmp_path):
    def stop_after_first_epoch(trainer, row):
        trainer.stop.requested = True

    cfg = tiny_config("algo=sac_lag", "collector.total_frames=600")
    part = Trainer(cfg, tmp_path, stop_after_first_epoch, hooks={"recorder": Recorder()})
    part.run()
    steps = part.counters.grad_steps
    assert steps > 0 and part.state_dict()["hooks"]["recorder"] == {"steps": steps}
    cfg.resume = str(tmp_path)
    recorder = Recorder()
    resumed = Trainer(cfg, tmp_path / "unused", hooks={"recorder": recorder})
    assert recorder.steps == steps  # restored with the run
    resumed.run()
    assert recorder.steps == resumed.counters.grad_steps > steps


def test_unknown_points_and_names_are_refused(tiny_config, tmp_path):
    trainer = Trainer(tiny_config("algo=sac"), tmp_path)
    with pytest.raises(ValueError, match="Unknown hook point 'before_collect'"):
        trainer.register_op("before_collect", print)
    recorder = Recorder()
    recorder.register(trainer, "recorder")
    with pytest.raises(ValueError, match="'recorder' is registered already"):
        trainer.register_module("recorder", recorder)
    assert set(HOOK_POINTS) == {
        "after_collect", "after_update", "after_evaluation", "epoch_end", "final_evaluation"
    }


def test_on_epoch_end_is_an_epoch_end_op(tiny_config, tmp_path):
    seen = []
    recorder = Recorder()
    train(tiny_config("algo=ppo", "collector.total_frames=400"), tmp_path,
          on_epoch_end=lambda trainer, row: seen.append((type(trainer).__name__, row["epoch"])),
          hooks={"recorder": recorder})
    assert seen == [("Trainer", 1), ("Trainer", 2)]
    # After the hooks' epoch_end ops.
    assert [row["epoch"] for row in recorder.rows] == [1, 2]
