"""The console scripts as a user runs them: s3rl-train, sweeps (basic, joblib, submitit), s3rl-eval."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# Each test starts the console scripts (a few seconds of imports each): all slow.
pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent
TINY = ["experiment=tiny", "collector.total_frames=200", "collector.frames_per_epoch=200"]


def run(script: str, *args: str, cwd: Path, **env_vars: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "HYDRA_FULL_ERROR": "0", **env_vars}
    return subprocess.run(
        [str(BIN / script), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )


def test_train_then_evaluate(tmp_path):
    run_dir = tmp_path / "run"
    out = run("s3rl-train", *TINY, "algo=sac_lag", f"hydra.run.dir={run_dir}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "| run | episodes | reward | cost | length | safe steps (%) |" in out.stdout
    final = json.loads((run_dir / "final_eval.json").read_text())
    assert final["episodes"] == 2
    assert (run_dir / ".hydra" / "config.yaml").is_file()  # the resolved config

    eval_dir = tmp_path / "eval"
    out = run(
        "s3rl-eval", f"checkpoint={run_dir}", "episodes=3", "max_steps=30",
        f"hydra.run.dir={eval_dir}", cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    result = json.loads((eval_dir / "eval.json").read_text())
    assert result["episodes"] == 3 and result["length_mean"] == 30.0
    assert "sac_lag SafetyHalfCheetahVelocity-v1 seed 10" in out.stdout

    # A video through MuJoCo's offscreen renderer (EGL here; see docs/recipes.md).
    video = tmp_path / "episode.gif"
    out = run(
        "s3rl-eval", f"checkpoint={run_dir}", "episodes=1", "max_steps=8", "video=true",
        f"video_path={video}", f"hydra.run.dir={tmp_path / 'eval_video'}", cwd=tmp_path,
        MUJOCO_GL="egl",
    )
    assert out.returncode == 0, out.stderr
    import imageio.v2 as imageio

    frames = imageio.mimread(video)
    assert len(frames) == 8 and frames[0].ndim == 3 and frames[0].std() > 0


def test_a_compiled_run_prints_no_third_party_noise(tmp_path):
    # What `make train` printed: tensordict's FutureWarning about a torch._dynamo option, its
    # lock_() warning under torch.compile (ours: SACLagLoss no longer locks inside the graph)
    # and MuJoCo's settotalmass deprecation (Gymnasium's half_cheetah.xml). None of them now.
    out = run(
        "s3rl-train", *TINY, "algo=sac_lag", "compile=true", f"hydra.run.dir={tmp_path / 'r'}",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    for noise in ("inline_inbuilt_nn_modules", "lock_()", "settotalmass"):
        assert noise not in out.stderr + out.stdout, noise
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_bad_override_fails_before_training(tmp_path):
    out = run("s3rl-train", *TINY, "algo.update_per_step=-2", f"hydra.run.dir={tmp_path / 'r'}",
              cwd=tmp_path)
    assert out.returncode == 2
    assert "Invalid value -2.0 for 'algo.update_per_step'" in out.stderr
    assert not (tmp_path / "r" / "metrics.csv").exists()
    out = run("s3rl-train", *TINY, "algo=trpo_lag", cwd=tmp_path)
    assert out.returncode != 0 and "Available options in 'algo'" in out.stderr
    assert "ppo_lag" in out.stderr and "s3rl_ddpg_lag" in out.stderr


def test_eval_rejects_a_corrupt_checkpoint(tmp_path):
    bad = tmp_path / "state.pt"
    bad.write_bytes(b"not a checkpoint")
    out = run("s3rl-eval", f"checkpoint={bad}", f"hydra.run.dir={tmp_path / 'e'}", cwd=tmp_path)
    assert out.returncode == 2 and "is corrupt or not a s3rl-torchrl checkpoint" in out.stderr


@pytest.mark.parametrize("launcher", ["basic", "parallel", "local_submitit"])
def test_two_seed_multirun(tmp_path, launcher):
    sweep_dir = tmp_path / "sweep"
    args = [*TINY, "algo=sac", "seed=10,20", f"hydra.sweep.dir={sweep_dir}"]
    if launcher != "basic":
        args.append(f"hydra/launcher={launcher}")
    out = run("s3rl-train", "-m", *args, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    finals = sorted(sweep_dir.glob("*/final_eval.json"))
    assert [p.parent.name for p in finals] == [
        "sac_SafetyHalfCheetahVelocity-v1_seed10",
        "sac_SafetyHalfCheetahVelocity-v1_seed20",
    ]
    rewards = [json.loads(p.read_text())["reward_mean"] for p in finals]
    assert rewards[0] != rewards[1]  # the seeds really differ


def test_own_config_dir_adds_options_next_to_the_packaged_ones(tmp_path):
    # docs/recipes.md: a user's experiment in a directory of theirs, building on `tiny`.
    mine = tmp_path / "my_configs" / "experiment"
    mine.mkdir(parents=True)
    (mine / "short.yaml").write_text(
        "# @package _global_\ndefaults:\n  - tiny\ncollector:\n  total_frames: 400\n"
    )
    out = run("s3rl-train", "--config-dir", str(tmp_path / "my_configs"), "experiment=short",
              "--cfg", "job", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "total_frames: 400" in out.stdout  # the user's value
    assert "frames_per_batch: 100" in out.stdout and "- 32" in out.stdout  # tiny's, inherited
