"""What ``s3rl-train`` refuses before Hydra writes anything or a sweep starts a job
(recipes/launch_checks.py): a bad value, an unwritable or taken run directory, a sweep with a bad
job, a Slurm launcher without Slurm. Each is one line per problem, exit status 2, and no file
written; run directories are unique per command."""

from __future__ import annotations

import datetime
import itertools
import os
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import open_dict, read_write

from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.recipes import launch_checks as checks
from s3rl_torchrl.trainer import register_configs
from s3rl_torchrl.trainer.run_lock import LOCK_FILE, RunLock
from tests.trainer.test_checkpoint_integrity import make_read_only


@contextmanager
def hydra_app():
    """Hydra initialised as ``s3rl-train`` initialises it (what the callbacks run inside)."""
    register_configs()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        yield


def composed(*overrides: str, task: list[str] | None = None):
    """The config the callbacks get, ``hydra`` node included; ``task``: the command's task
    overrides as a sweep gives them (``collector.total_frames=0,600``)."""
    cfg = compose(config_name="train", overrides=list(overrides), return_hydra_config=True)
    with read_write(cfg), open_dict(cfg):
        cfg.hydra.runtime.choices.algo = "s3rl"  # set by a launch, not by compose
        if task is not None:
            cfg.hydra.overrides.task = task
    return cfg


def refused(capsys, call) -> list[str]:
    """Run ``call``; it must exit with status 2. The lines it printed on stderr."""
    with pytest.raises(SystemExit) as exit_:
        call()
    assert exit_.value.code == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return captured.err.strip().splitlines()


def tree(root: Path) -> dict[str, tuple[bytes, int]]:
    return {
        str(p.relative_to(root)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in root.rglob("*")
        if p.is_file()
    }


@pytest.mark.parametrize(
    "override, named",
    [
        ("seed=-1", "Invalid value -1 for 'seed': a seed must be an integer from 0 to 4294967295"),
        (f"seed={2**64}", f"Invalid value {2**64} for 'seed': a seed must be an integer from 0"),
        ("seeds=[1,-2]", "Invalid value -2 for 'seeds[1]'"),
        ("collector.total_frames=0", "Invalid value 0 for 'collector.total_frames'"),
    ],
)
def test_a_bad_value_is_one_line_and_writes_nothing(override, named, tmp_path, capsys):
    run_dir = tmp_path / "outputs" / "run"
    with hydra_app():
        cfg = composed("experiment=tiny", "algo=sac", override, f"hydra.run.dir={run_dir}")
        (line,) = refused(capsys, lambda: checks.LaunchChecks().on_run_start(cfg))
    assert line.startswith("s3rl-train: ") and named in line
    assert list(tmp_path.iterdir()) == []


def test_a_device_torch_cannot_use_is_refused(tmp_path, capsys, monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)  # as on a CPU-only build
    with hydra_app():
        cfg = composed("experiment=tiny", "device=cuda", f"hydra.run.dir={tmp_path / 'run'}")
        (line,) = refused(capsys, lambda: checks.LaunchChecks().on_run_start(cfg))
    assert "Invalid value 'cuda' for 'device'" in line and "use device=cpu" in line
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_output_directory_is_one_line(tmp_path, capsys, monkeypatch):
    read_only = tmp_path / "read_only"
    read_only.mkdir()
    make_read_only(monkeypatch, read_only)
    with hydra_app():
        cfg = composed("experiment=tiny", f"hydra.run.dir={read_only / 'outputs' / 'run'}")
        (line,) = refused(capsys, lambda: checks.LaunchChecks().on_run_start(cfg))
    assert line.startswith(f"s3rl-train: Cannot write in '{read_only / 'outputs'}'")
    assert line.endswith("Give a directory you can write: hydra.run.dir=<dir>.")
    assert list(read_only.iterdir()) == []


def finished_run(run_dir: Path) -> dict[str, tuple[bytes, int]]:
    """What a run that ended leaves (in part): its metrics, Hydra's files, its log and lock."""
    (run_dir / ".hydra").mkdir(parents=True)
    (run_dir / ".hydra" / "config.yaml").write_text("eval:\n  final_episodes: 3\n")
    (run_dir / "metrics.csv").write_text("frames,epoch\n200,1\n")
    (run_dir / "train.log").write_text("[INFO] - the first run\n")
    return tree(run_dir)


def test_a_command_into_another_runs_directory_writes_nothing_there(tmp_path, capsys):
    run_dir = tmp_path / "run"
    before = finished_run(run_dir)
    with hydra_app():
        cfg = composed("experiment=tiny", "eval.final_episodes=2", f"hydra.run.dir={run_dir}")
        (line,) = refused(capsys, lambda: checks.LaunchChecks().on_run_start(cfg))
    assert line == (
        f"s3rl-train: {run_dir} already holds a run (.hydra, metrics.csv, train.log); continue "
        f"it with resume={run_dir} or train into a new directory. Its files are untouched."
    )
    assert tree(run_dir) == before  # no lock file made, Hydra's files as the first run wrote


def test_a_command_into_a_directory_in_training_writes_nothing_there(tmp_path, capsys):
    # The first command holds the lock from before Hydra wrote its files (here: this process,
    # through another open file, which flock refuses as another process's).
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    first = RunLock(run_dir)
    try:
        before = tree(run_dir)
        with hydra_app():
            cfg = composed("experiment=tiny", f"hydra.run.dir={run_dir}")
            (line,) = refused(capsys, lambda: checks.LaunchChecks().on_run_start(cfg))
        assert line.startswith(f"s3rl-train: {run_dir} is in use: another process (pid ")
        assert tree(run_dir) == before
    finally:
        first.release()


def test_the_claimed_directory_is_the_trainers(tmp_path):
    # The lock the callback takes is the one the trainer continues with (flock would refuse the
    # trainer a second lock of the same file); a second trainer is still refused.
    run_dir = tmp_path / "run"
    with hydra_app():
        checks.LaunchChecks().on_run_start(composed("experiment=tiny", f"hydra.run.dir={run_dir}"))
    claimed = RunLock.take(run_dir)
    assert claimed.held and (run_dir / LOCK_FILE).read_text() == f"{os.getpid()}\n"
    from s3rl_torchrl.trainer.run_lock import RunInUseError

    with pytest.raises(RunInUseError):
        RunLock.take(run_dir)
    claimed.release()


def test_two_commands_in_the_same_second_get_directories_of_their_own(monkeypatch):
    # The default run directory ends with the command's start time; two commands started in
    # one second shared it (3 of 7 simultaneous launches).
    from hydra.core import utils as hydra_utils

    # Each command's clock reads one microsecond after the previous one's, in one second.
    starts = (datetime.datetime(2026, 1, 1, 12, 0, 0, micro) for micro in itertools.count(1))

    class Clock(datetime.datetime):
        @classmethod
        def now(cls, tz=None):
            return next(starts)

    monkeypatch.setattr(hydra_utils, "datetime", Clock)  # what Hydra's ${now:...} reads
    with hydra_app():
        first, second = (composed("experiment=tiny") for _ in range(2))
        directories = [str(cfg.hydra.run.dir) for cfg in (first, second)]
        sweeps = [str(cfg.hydra.sweep.dir) for cfg in (first, second)]
    assert directories[0] != directories[1] and sweeps[0] != sweeps[1]
    assert directories[0].startswith("outputs/s3rl/SafetyHalfCheetahVelocity-v1/seed10/2026-01-01")


def test_a_sweep_with_bad_jobs_names_them_all_and_starts_none(tmp_path, capsys):
    sweep_dir = tmp_path / "multirun"
    with hydra_app():
        cfg = composed(
            "experiment=tiny",
            f"hydra.sweep.dir={sweep_dir}",
            task=["experiment=tiny", "collector.total_frames=0,600", "seed=1,-1"],
        )
        lines = refused(capsys, lambda: checks.LaunchChecks().on_multirun_start(cfg))
    # Jobs: (0, 1), (0, -1), (600, 1), (600, -1): only (600, 1) is valid.
    assert lines[0] == "s3rl-train: 3 of the sweep's 4 jobs would be refused, so none was started:"
    assert [line.split(":")[1].strip() for line in lines[1:]] == [
        "experiment=tiny collector.total_frames=0 seed=1",
        "experiment=tiny collector.total_frames=0 seed=-1",
        "experiment=tiny collector.total_frames=600 seed=-1",
    ]
    assert "Invalid value 0 for 'collector.total_frames'" in lines[1]
    assert "Invalid value -1 for 'seed'" in lines[3]
    assert not sweep_dir.exists()


def test_a_valid_sweep_passes(tmp_path):
    with hydra_app():
        cfg = composed("experiment=tiny", f"hydra.sweep.dir={tmp_path / 'multirun'}",
                       task=["experiment=tiny", "algo=sac,sac_lag", "seed=1,2"])
        jobs = checks.sweep_jobs(cfg)
        checks.LaunchChecks().on_multirun_start(cfg)
    assert len(jobs) == 4 and all(job.problem is None for job in jobs)
    # Each in a directory of its own, named as configs/train.yaml names it under the basic
    # sweeper (no trial number).
    assert [job.run_dir for job in jobs] == [
        tmp_path / "multirun" / f"{algo}_SafetyHalfCheetahVelocity-v1_seed{seed}"
        for algo in ("sac", "sac_lag") for seed in (1, 2)
    ]


def test_a_sweep_whose_jobs_share_a_directory_starts_none(tmp_path, capsys):
    # A sweep over a key the default directory's name leaves out: both values of the target
    # would train into <algo>_<task>_seed1, the second refusing the first's files mid-sweep.
    sweep_dir = tmp_path / "multirun"
    with hydra_app():
        cfg = composed("experiment=tiny", f"hydra.sweep.dir={sweep_dir}",
                       task=["experiment=tiny", "algo.lagrangian_target=0.5,0.7", "seed=1"])
        lines = refused(capsys, lambda: checks.LaunchChecks().on_multirun_start(cfg))
        assert lines[0] == ("s3rl-train: 2 of the sweep's 2 jobs would train into a directory "
                            "another of them trains into, so none was started:")
        shared = sweep_dir / "s3rl_SafetyHalfCheetahVelocity-v1_seed1"
        assert lines[1] == (f"s3rl-train:   {shared}: experiment=tiny algo.lagrangian_target=0.5 "
                            "seed=1 | experiment=tiny algo.lagrangian_target=0.7 seed=1")
        assert "hydra.sweep.subdir='job${hydra.job.num}'" in lines[2]
        assert not sweep_dir.exists()
        # Either advice gives each job its own directory, and the sweep passes.
        for subdir in ("${hydra.job.override_dirname}", "job${hydra.job.num}"):
            cfg = composed("experiment=tiny", f"hydra.sweep.dir={sweep_dir}",
                           f"hydra.sweep.subdir={subdir}",
                           task=["experiment=tiny", "algo.lagrangian_target=0.5,0.7", "seed=1"])
            checks.LaunchChecks().on_multirun_start(cfg)
            assert len({job.run_dir for job in checks.sweep_jobs(cfg)}) == 2


def test_a_sweeps_jobs_are_its_parameters_product_the_first_varying_slowest():
    # Written out by hand: what `--multirun task=a,b algo=s3rl,sac_lag seed=range(10,31,10)`
    # launches, with a fixed override kept in every job and a repeated key taking its place.
    jobs = checks.sweep_overrides(
        ["task=a,b", "eval.delivery_epochs=10", "algo=s3rl,sac_lag", "seed=range(10,31,10)",
         "eval.delivery_epochs=0"]
    )
    expected = [
        [f"task={task}", "eval.delivery_epochs=0", f"algo={algo}", f"seed={seed}"]
        for task in ("a", "b") for algo in ("s3rl", "sac_lag") for seed in (10, 20, 30)
    ]
    assert jobs == expected


def test_slurm_without_slurm_is_one_line(tmp_path, capsys, monkeypatch):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    monkeypatch.setattr(checks.shutil, "which", lambda name: None)
    with hydra_app():
        cfg = composed("experiment=tiny", "hydra/launcher=slurm",
                       f"hydra.sweep.dir={tmp_path / 'multirun'}", task=["experiment=tiny"])
        (line,) = refused(capsys, lambda: checks.LaunchChecks().on_multirun_start(cfg))
    assert line.startswith("s3rl-train: hydra/launcher=slurm submits each job with Slurm's sbatch")


def test_the_cli_runs_the_checks_before_hydra_writes(tmp_path):
    # Through the command line: a bad seed leaves no run directory behind.
    import subprocess

    train_cli = str(Path(sys.executable).with_name("s3rl-train"))
    done = subprocess.run([train_cli, "experiment=tiny", "seed=-1"], cwd=tmp_path,
                          capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "s3rl-train: Invalid value -1 for 'seed': a seed must be an integer from 0 to "
        "4294967295 (2**32 - 1)."
    ]
    assert list(tmp_path.iterdir()) == []
