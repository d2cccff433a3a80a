"""Resume identity: an interrupted and resumed run is the uninterrupted run, row for row.

The checkpoint holds what the next step depends on (envs' simulators and generators, the
collector's carrier, the n-step transform's held frames, every random stream, the epoch's
partial statistics), so ``metrics.csv`` (timing aside) and ``final_eval.json`` are identical
whether the run was stopped or not (docs/recipes.md, "Resume")."""

from __future__ import annotations

import json
import os
import signal

import pytest

from s3rl_torchrl.trainer import Trainer, train, train_seeds
from s3rl_torchrl.trainer.metrics import read_metrics
from s3rl_torchrl.trainer.multiseed import MultiSeedTrainer

TIMING = ("eval/seconds",)


def rows(run_dir):
    return [{k: v for k, v in r.items() if k not in TIMING} for r in read_metrics(run_dir)]


def final(run_dir):
    return json.loads((run_dir / "final_eval.json").read_text())


def sigterm_at_step(cls, step, monkeypatch):
    """A real SIGTERM in the middle of the run's gradient steps (the handler stops the loop at
    the next safe point and writes a checkpoint)."""
    original = cls._gradient_step

    def step_then_signal(self):
        original(self)
        lead = self.members[0] if hasattr(self, "members") else self
        if lead.counters.grad_steps == step:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(cls, "_gradient_step", step_then_signal)


def crash_after_epoch(epoch):
    """A crash (as kill -9) after the checkpoint of ``epoch``: what it logged after that
    checkpoint is dropped on resume."""

    def callback(trainer, row):
        if row["epoch"] == epoch + 1:
            raise KeyboardInterrupt(f"simulated kill -9 after the checkpoint of epoch {epoch}")

    return callback


CASES = [
    # (task, algo, interruption): each family on a velocity, a Goal and a Circle task.
    ("SafetyHalfCheetahVelocity-v1", "sac_lag", "sigterm"),
    ("SafetyHalfCheetahVelocity-v1", "ddpg_lag", "crash"),
    ("SafetyHalfCheetahVelocity-v1", "ppo_lag", "sigterm"),
    ("SafetyPointGoal1-v0", "s3rl", "crash"),
    ("SafetyPointGoal1-v0", "ddpg_lag", "sigterm"),
    ("SafetyPointGoal1-v0", "ppo_lag", "crash"),
    ("SafetyPointCircle1-v0", "s3rl", "sigterm"),
    ("SafetyPointCircle1-v0", "ddpg_lag", "sigterm"),
    ("SafetyPointCircle1-v0", "ppo_lag", "crash"),
]


@pytest.mark.slow
@pytest.mark.parametrize("task, algo, interruption", CASES)
def test_resumed_run_is_the_uninterrupted_run(task, algo, interruption, tiny_config, tmp_path,
                                              monkeypatch):
    cfg = tiny_config(f"task={task}", f"algo={algo}", "collector.total_frames=800")
    train(cfg, tmp_path / "full")
    if interruption == "sigterm":
        # Mid-epoch: between two gradient steps of the second epoch's batches.
        with monkeypatch.context() as patch:
            sigterm_at_step(Trainer, 37, patch)
            part = train(cfg, tmp_path / "part")
        assert part.status == "interrupted" and part.counters.epochs == 1
    else:
        with pytest.raises(KeyboardInterrupt):
            train(cfg, tmp_path / "part", on_epoch_end=crash_after_epoch(2))
    cfg.resume = str(tmp_path / "part")
    resumed = train(cfg, tmp_path / "unused")
    assert resumed.status == "finished"
    assert rows(tmp_path / "part") == rows(tmp_path / "full")
    assert final(tmp_path / "part") == final(tmp_path / "full")


@pytest.mark.slow
def test_resumed_group_is_the_uninterrupted_group(tiny_config, tmp_path, monkeypatch):
    cfg = tiny_config("algo=s3rl", "seeds=[3,4]", "collector.total_frames=800")
    train_seeds(cfg, tmp_path / "full")
    with monkeypatch.context() as patch:
        sigterm_at_step(MultiSeedTrainer, 70, patch)
        assert train_seeds(cfg, tmp_path / "part").status == "interrupted"
    cfg.resume = str(tmp_path / "part")
    train_seeds(cfg, tmp_path / "unused")
    for seed in (3, 4):
        assert rows(tmp_path / f"part/seed{seed}") == rows(tmp_path / f"full/seed{seed}")
        assert final(tmp_path / f"part/seed{seed}") == final(tmp_path / f"full/seed{seed}")


def test_resuming_a_finished_run_keeps_its_final_evaluation(tiny_config, tmp_path, capsys):
    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    saved = (tmp_path / "final_eval.json").read_text()
    cfg.resume = str(tmp_path)
    again = train(cfg, tmp_path / "unused")
    assert again.status == "finished"
    assert (tmp_path / "final_eval.json").read_text() == saved
    assert again.final_eval.reward_mean == json.loads(saved)["reward_mean"]
    assert "not recomputed" in capsys.readouterr().out


@pytest.mark.slow
def test_a_bullet_run_says_its_resume_is_inexact(tiny_config, tmp_path, capsys):
    pytest.importorskip("bullet_safety_gym")
    cfg = tiny_config("task=SafetyBallRun-v0", "algo=sac_lag", "collector.total_frames=400")

    def stop(trainer, row):
        trainer.stop.requested = True

    train(cfg, tmp_path, on_epoch_end=stop)
    cfg.resume = str(tmp_path)
    train(cfg, tmp_path / "unused")
    assert "inexactly" in capsys.readouterr().out
    resume = json.loads((tmp_path / "config.json").read_text())["resumes"][-1]
    assert resume["exact"] is False and "pybullet" in resume["inexact_reason"]


@pytest.mark.slow
def test_kill_9_after_a_checkpoint_then_resume_alone_is_the_uninterrupted_run(tmp_path):
    # Through the command line, as a user does: the run is killed (SIGKILL: no handler runs)
    # once it has checkpointed, then `s3rl-train resume=<run>` alone continues it.
    import subprocess
    import sys
    import time
    from pathlib import Path

    train_cli = str(Path(sys.executable).with_name("s3rl-train"))
    args = ["experiment=tiny", "algo=sac_lag", "task=SafetyHopperVelocity-v1",
            "collector.total_frames=1000", "logger.progress_bar=false"]
    full, part = tmp_path / "full", tmp_path / "part"
    subprocess.run([train_cli, *args, f"hydra.run.dir={full}"], check=True, capture_output=True)
    process = subprocess.Popen([train_cli, *args, f"hydra.run.dir={part}"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = part / "checkpoints" / "latest" / "manifest.json"
    deadline = time.monotonic() + 300
    while process.poll() is None and time.monotonic() < deadline:
        if manifest.is_file() and len(read_metrics(part)) >= 2:
            break
        time.sleep(0.05)
    process.kill()
    process.wait()
    assert not (part / "final_eval.json").exists(), "the run ended before it was killed"
    done = subprocess.run([train_cli, f"resume={part}"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert rows(part) == rows(full)
    assert final(part) == final(full)


@pytest.mark.slow
def test_an_inexact_resume_in_the_middle_of_episodes_cuts_them(tiny_config, tmp_path):
    # A checkpoint whose env copies are mid-episode (50 of BallRun's 100 steps per copy), with
    # n-step windows held back: the resumed envs restart their episodes, so the held frames'
    # episodes end there as a time limit would end them (a CarRun evidence run resumed this way
    # stopped with "step_count jumps without an episode end").
    pytest.importorskip("bullet_safety_gym")
    cfg = tiny_config(
        "task=SafetyBallRun-v0", "algo=sac_lag", "algo.n_step=3", "collector.total_frames=400",
        "collector.frames_per_epoch=100",
    )

    def stop(trainer, row):
        trainer.stop.requested = True

    part = train(cfg, tmp_path, on_epoch_end=stop)
    assert part.status == "interrupted" and part.counters.frames == 100
    cfg.resume = str(tmp_path)
    trainer = Trainer(cfg, tmp_path / "unused")
    held = trainer.updates.nstep.held_frames
    assert held["step_count"][..., -1, 0].tolist() == [49, 49]  # mid-episode on both copies
    assert held["next", "done"][..., -1, 0].tolist() == [True, True]
    assert held["next", "truncated"][..., -1, 0].tolist() == [True, True]
    assert not held["next", "terminated"].any()
    assert not held["next", "done"][..., :-1, :].any()  # only the last held step ends one
    assert trainer.run().status == "finished"
