"""Resume identity: an interrupted and resumed run is the uninterrupted run, row for row.

The checkpoint holds what the next step depends on (envs' simulators and generators, the
collector's carrier, the n-step transform's held frames, every random stream, the epoch's
partial statistics), so ``metrics.csv`` (timing aside) and ``final_eval.json`` are identical
whether the run was stopped or not (docs/recipes.md, "Resume"); so is every other file under the
run directory (:func:`assert_same_files`): the loggers' files, the config, the checkpoints."""

from __future__ import annotations

import json
import os
import signal
from fnmatch import fnmatch
from pathlib import Path

import pytest
import torch

from s3rl_torchrl.trainer import Trainer, train, train_seeds
from s3rl_torchrl.trainer.metrics import read_metrics
from s3rl_torchrl.trainer.multiseed import MultiSeedTrainer
from s3rl_torchrl.trainer.run_lock import LOCK_FILE

TIMING = ("eval/seconds",)
# What differs between two runs whatever they did: the timing scalar's file (the CSV logger's
# copy of the eval/seconds column), the lock file (the owner's process id) and Hydra's records
# of each invocation (a resume's go to <run>/resumes/<time>; the killed one's log is cut short).
TIMING_FILES = ("logs/*/scalars/eval/seconds.csv",)
INVOCATION_FILES = (LOCK_FILE, ".hydra/*", "train.log", "resumes/*")


def rows(run_dir):
    return [{k: v for k, v in r.items() if k not in TIMING} for r in read_metrics(run_dir)]


def same_value(a, b) -> bool:
    if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
        return isinstance(a, torch.Tensor) and isinstance(b, torch.Tensor) and (
            a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
        )
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_value(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b))
    return a == b


def checkpoint_state(file: Path) -> dict:
    """A checkpoint's state without what names the invocation (``config.resume``), what
    numbers the collector's own trajectories (``traj_ids`` count from the collector's start),
    MuJoCo's serialised ``MjData`` (it holds the simulator's scratch memory besides its
    state: the same next steps follow from both, which the metrics check) and the sizes of the
    files that hold timing (the digits of a duration vary)."""

    def kept(value):
        if isinstance(value, dict):
            return {k: kept(v) for k, v in value.items() if k != "traj_ids"}
        return value

    state = kept(torch.load(file, map_location="cpu", weights_only=True))
    state["config"].pop("resume")
    envs = [state.get("test_env"), (state.get("collector") or {}).get("train_env")]
    for env in filter(None, envs):
        for copy in env["copies"]:
            copy.pop("data")
    if "appended_files" in state:  # checkpoints/latest (checkpoints/best: the policy only)
        state["appended_files"] = {
            name: size
            for name, size in state["appended_files"].items()
            if not any(fnmatch(name, p) for p in ("metrics.csv", *TIMING_FILES))
        }
    return state


def stored_rows(file: Path) -> bytes:
    """The filled rows of a replay buffer's memmap (the rest is uninitialised memory)."""
    storage = next(p for p in file.parents if p.name == "storage")
    filled = json.loads((storage / "storage_metadata.json").read_text())["len"]
    meta = json.loads((file.parent / "meta.json").read_text())[file.stem]
    data = file.read_bytes()
    return data[: len(data) // meta["shape"][0] * filled]


def content(run_dir: Path, name: str):
    """What a file of a run holds, as a resumed and an uninterrupted run must share it."""
    file = run_dir / name
    if name == "metrics.csv" or name.endswith("/metrics.csv"):
        return rows(file.parent)
    if name.endswith("config.json"):  # the resumed run's also records its resumes
        saved = json.loads(file.read_text())
        return {k: v for k, v in saved.items() if k not in ("resume", "resumes")}
    if name.endswith("state.pt"):
        return checkpoint_state(file)
    if name.endswith("manifest.json"):  # digests of the files compared one by one
        return sorted(json.loads(file.read_text())["files"])
    if name.endswith("meta.json"):  # the same keys, in the order they were first written
        return json.loads(file.read_text())
    if file.suffix == ".memmap" and "storage" in Path(name).parts:  # a buffer's storage
        return stored_rows(file)
    return file.read_bytes()


def assert_same_files(part: Path, full: Path) -> None:
    """Every file under the resumed run's directory is the uninterrupted run's: the same
    paths, and the same content up to timing (:func:`content`)."""

    def listing(run_dir):
        names = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()}
        return {n for n in names if not any(fnmatch(n, p) for p in INVOCATION_FILES)}

    names = listing(full)
    assert listing(part) == names
    for name in sorted(names):
        if any(fnmatch(name, p) for p in TIMING_FILES):
            continue
        assert same_value(content(part, name), content(full, name)), name


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
    assert_same_files(tmp_path / "part", tmp_path / "full")


@pytest.mark.parametrize("interruption", ["sigterm", "crash"])
def test_every_file_of_a_resumed_run_is_the_uninterrupted_runs(interruption, tiny_config,
                                                               tmp_path, monkeypatch):
    # Hopper ends episodes in every batch, so lambda's scalars (logs/.../scalars/lagrangian/,
    # one row per batch) are written between checkpoints (every second epoch here): a crash
    # after epoch 3 leaves rows past the checkpoint of epoch 2 in every file the run appends to.
    cfg = tiny_config("algo=sac_lag", "task=SafetyHopperVelocity-v1",
                      "collector.total_frames=800", "save_interval=2")
    train(cfg, tmp_path / "full")
    if interruption == "sigterm":
        with monkeypatch.context() as patch:
            sigterm_at_step(Trainer, 90, patch)  # in the third epoch
            assert train(cfg, tmp_path / "part").status == "interrupted"
    else:
        with pytest.raises(KeyboardInterrupt):
            train(cfg, tmp_path / "part", on_epoch_end=crash_after_epoch(2))
        lagrangian = next((tmp_path / "part").glob("logs/*/scalars/lagrangian/value.csv"))
        steps = [int(line.split(",")[0]) for line in lagrangian.read_text().splitlines()]
        assert max(steps) > 400  # logged after the checkpoint of epoch 2 (400 frames)
    cfg.resume = str(tmp_path / "part")
    assert train(cfg, tmp_path / "unused").status == "finished"
    assert_same_files(tmp_path / "part", tmp_path / "full")


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
    out = capsys.readouterr().out
    assert "not recomputed" in out
    assert f"Resuming {tmp_path} at frame 200 of 200\n" in out  # says it resumed, and where


def test_an_interrupted_run_exits_with_the_signals_status(tiny_config, tmp_path, monkeypatch):
    # The shell's convention (128 + the signal's number), so that `s3rl-train ... && next`
    # stops at an unfinished run; the recipe exits with it (recipes/train.py).
    cfg = tiny_config("algo=sac", "collector.total_frames=400")
    sigterm_at_step(Trainer, 10, monkeypatch)
    result = train(cfg, tmp_path)
    assert result.status == "interrupted" and result.exit_status == 128 + signal.SIGTERM == 143


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
    assert_same_files(part, full)


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_the_cli_exits_non_zero_after_an_interrupt_and_says_how_to_continue(signum, tmp_path):
    import subprocess
    import sys
    import time

    train_cli = str(Path(sys.executable).with_name("s3rl-train"))
    run = tmp_path / "run"
    process = subprocess.Popen(
        [train_cli, "experiment=tiny", "algo=sac", "collector.total_frames=100000",
         f"hydra.run.dir={run}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    deadline = time.monotonic() + 300
    while process.poll() is None and time.monotonic() < deadline:
        if (run / "metrics.csv").is_file() and len(read_metrics(run)) >= 1:
            break
        time.sleep(0.05)
    process.send_signal(signum)
    out, _ = process.communicate(timeout=300)
    assert process.returncode == 128 + signum  # 143 for SIGTERM, 130 for Ctrl-C
    assert f"continue with resume={run}" in out


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


def test_a_resume_cuts_back_every_file_the_run_appends_to(tmp_path):
    from s3rl_torchrl.trainer.metrics import appended_files, cut_back_to_checkpoint

    scalars = tmp_path / "logs" / "run" / "scalars"
    (scalars / "lagrangian").mkdir(parents=True)
    files = {
        "metrics.csv": "frames,epoch\n200,1\n",
        "logs/run/scalars/epoch.csv": "200,1\n",
        "logs/run/scalars/lagrangian/value.csv": "100,0.5\n200,0.7\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "notes.txt").write_text("the user's\n")
    recorded = appended_files(tmp_path)  # what the checkpoint at 200 frames holds
    assert set(recorded) == set(files)
    # The interrupted run goes on after its checkpoint, then is killed.
    for name, line in [("metrics.csv", "400,2\n"), ("logs/run/scalars/epoch.csv", "400,2\n"),
                       ("logs/run/scalars/lagrangian/value.csv", "300,0.9\n")]:
        with (tmp_path / name).open("a") as f:
            f.write(line)
    (scalars / "lagrangian" / "episode_cost.csv").write_text("300,12.0\n")
    cut_back_to_checkpoint(tmp_path, recorded, frames=200)
    assert {name: (tmp_path / name).read_text() for name in files} == files
    assert not (scalars / "lagrangian" / "episode_cost.csv").exists()
    assert (tmp_path / "notes.txt").read_text() == "the user's\n"


def test_a_checkpoint_without_the_record_drops_rows_past_its_frames_at_any_depth(tmp_path):
    from s3rl_torchrl.trainer.metrics import cut_back_to_checkpoint

    nested = tmp_path / "logs" / "run" / "scalars" / "lagrangian" / "value.csv"
    nested.parent.mkdir(parents=True)
    nested.write_text("100,0.5\n200,0.7\n300,0.9\n")
    (tmp_path / "metrics.csv").write_text("epoch,frames\n1,200\n2,400\n")
    cut_back_to_checkpoint(tmp_path, None, frames=200)
    assert nested.read_bytes() == b"100,0.5\n200,0.7\n"
    assert (tmp_path / "metrics.csv").read_text().splitlines() == ["epoch,frames", "1,200"]


# ------------------------------------------------------------------------------ trainer/resume.py
# What a resume reads, checks and restores (docs/architecture.md, "Resume"), tested directly.
def test_check_compatible_names_every_changed_locked_key():
    from s3rl_torchrl.trainer.checkpoint import CheckpointError
    from s3rl_torchrl.trainer.resume import check_compatible

    saved = {"seed": 3, "network": {"actor_hidden": [32, 32]}, "algo": {"n_step": 1}}
    current = {"seed": 4, "network": {"actor_hidden": [64, 64]}, "algo": {}}
    check_compatible(saved, saved, ["seed", "network.actor_hidden", "algo.n_step"])
    with pytest.raises(CheckpointError) as refused:
        check_compatible(saved, current, ["seed", "network.actor_hidden", "task.name"])
    assert str(refused.value) == (
        "The checkpoint does not match the current configuration:\n"
        "  seed: checkpoint has 3, the current config has 4\n"
        "  network.actor_hidden: checkpoint has [32, 32], the current config has [64, 64]"
    )


def test_holds_run_finds_a_checkpoint_or_a_group(tmp_path):
    from s3rl_torchrl.trainer.resume import holds_run

    assert not holds_run(tmp_path)
    (tmp_path / "metrics.csv").write_text("frames\n")  # files, but no checkpoint to continue
    assert not holds_run(tmp_path)
    (tmp_path / "seeds.json").write_text('{"seeds": [1, 2]}')
    assert holds_run(tmp_path)


def test_resume_read_refuses_a_changed_locked_key_before_writing(tiny_config, tmp_path):
    from s3rl_torchrl.trainer.checkpoint import CheckpointError
    from s3rl_torchrl.trainer.resume import Resume

    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    cfg.resume = str(tmp_path)
    resume = Resume.read(cfg)
    assert resume.run_dir == tmp_path and resume.frames == 200
    assert resume.checkpoint_dir == tmp_path / "checkpoints" / "latest"
    other = tiny_config("algo=sac", "collector.total_frames=200", "network.actor_hidden=[64,64]")
    other.resume = str(tmp_path)
    with pytest.raises(CheckpointError) as refused:
        Resume.read(other)
    assert str(refused.value) == (
        "The checkpoint does not match the current configuration:\n"
        "  network.actor_hidden: checkpoint has [32, 32], the current config has [64, 64]"
    )
    cfg.collector.total_frames = 100
    with pytest.raises(CheckpointError) as refused:
        Resume.read(cfg)
    assert str(refused.value) == (
        "Invalid value 100 for 'collector.total_frames': the checkpoint has already collected "
        "200 frames; resume with collector.total_frames >= 200 (larger extends the run)."
    )
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files


def test_a_checkpoint_of_another_mujoco_release_is_refused_before_writing(tiny_config, tmp_path,
                                                                         monkeypatch):
    # The checkpoint's env snapshots were written by this process's MuJoCo; a process with
    # another release is refused before anything is built or any file of the run changes.
    from s3rl_torchrl.envs import state
    from s3rl_torchrl.trainer.checkpoint import CheckpointError
    from s3rl_torchrl.trainer.resume import Resume

    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    written = state.MUJOCO_VERSION
    monkeypatch.setattr(state, "MUJOCO_VERSION", "9.9.9")
    cfg.resume = str(tmp_path)
    with pytest.raises(CheckpointError) as refused:
        Resume.read(cfg)
    assert str(refused.value) == (
        f"Cannot resume this checkpoint: its simulator state was written by MuJoCo {written} "
        f"and this is MuJoCo 9.9.9, which cannot read it: resume with mujoco=={written} (the "
        "project pins its release in constraints.txt), or start the run again."
    )
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files


def test_a_restored_trainer_holds_its_checkpoints_state(tiny_config, tmp_path, monkeypatch,
                                                        capsys):
    # Stopped between two gradient steps of the second epoch (owed steps, the epoch's episodes
    # and losses, held n-step frames, envs mid-episode): the trainer built with resume= holds
    # the checkpoint's state exactly, random streams included, and says where it resumes.
    from s3rl_torchrl.trainer.checkpoint import save_checkpoint

    cfg = tiny_config("algo=sac_lag", "task=SafetyHopperVelocity-v1", "algo.n_step=3",
                      "collector.total_frames=600")
    with monkeypatch.context() as patch:
        sigterm_at_step(Trainer, 37, patch)
        part = train(cfg, tmp_path / "part")
    assert part.status == "interrupted" and part.counters.pending_updates > 0
    saved = tmp_path / "part" / "checkpoints" / "latest" / "state.pt"
    cfg.resume = str(tmp_path / "part")
    capsys.readouterr()
    trainer = Trainer(cfg, tmp_path / "unused")
    assert capsys.readouterr().out == (
        f"Resuming {tmp_path / 'part'} at frame {part.counters.frames} of 600\n"
    )
    assert trainer.inexact_resume is None and vars(trainer.counters) == vars(part.counters)
    save_checkpoint(tmp_path / "restored", trainer.state_dict())
    assert same_value(checkpoint_state(tmp_path / "restored" / "state.pt"),
                      checkpoint_state(saved))
    trainer.run_lock.release()
