"""One training process per run directory (trainer/run_lock.py): a second one is refused with
one line before it writes anything, and a killed owner leaves no stale lock."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from s3rl_torchrl.trainer import RunInUseError, Trainer, train
from s3rl_torchrl.trainer.run_lock import LOCK_FILE, RunLock

HOLD = textwrap.dedent(
    """
    import sys, time
    from s3rl_torchrl.trainer.run_lock import RunLock
    lock = RunLock(sys.argv[1])
    print("locked", flush=True)
    time.sleep(600)
    """
)


def test_a_second_trainer_into_a_training_run_is_refused_until_it_ends(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    first = Trainer(cfg, tmp_path)
    files = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(RunInUseError, match=f"pid {os.getpid()}"):
        Trainer(cfg, tmp_path)  # the same command twice, before either has logged an epoch
    assert sorted(p.name for p in tmp_path.iterdir()) == files  # the refused one wrote nothing
    first.run()  # the loop's end releases the lock: the run can be continued
    again = tiny_config("algo=sac", "collector.total_frames=300", "resume=" + str(tmp_path))
    assert train(again, tmp_path).status == "finished"


def test_a_killed_owner_leaves_no_stale_lock(tmp_path):
    src = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    owner = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], env=env,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert owner.stdout.readline().strip() == "locked"
        with pytest.raises(RunInUseError, match=f"pid {owner.pid}.*Its files are untouched"):
            RunLock(tmp_path)
    finally:
        owner.send_signal(signal.SIGKILL)
        owner.wait()
    lock = RunLock(tmp_path)  # the kernel dropped the dead owner's lock
    assert (tmp_path / LOCK_FILE).read_text() == f"{os.getpid()}\n"
    lock.release()


def test_the_cli_refuses_a_locked_run_directory_in_one_line(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    lock = RunLock(run_dir)
    train_cli = str(Path(sys.executable).with_name("s3rl-train"))
    done = subprocess.run([train_cli, "experiment=tiny", f"hydra.run.dir={run_dir}"],
                          capture_output=True, text=True)
    lock.release()
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].startswith(f"s3rl-train: {run_dir} is in use")
    assert "Traceback" not in done.stderr
    assert not (run_dir / "metrics.csv").exists() and not (run_dir / "config.json").exists()
