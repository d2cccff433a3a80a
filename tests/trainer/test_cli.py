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
    # train.log holds what the run printed: the command, the final table, the run directory.
    log = (run_dir / "train.log").read_text()
    assert "s3rl-train experiment=tiny" in log
    table_row = next(line for line in out.stdout.splitlines() if line.startswith("| sac_lag "))
    assert f"- {table_row}" in log and f"Run directory: {run_dir}" in log
    assert "Contrastive phases" not in out.stdout  # sac_lag has none

    # Without settings, s3rl-eval evaluates as the run did (tiny: 2 episodes of 50 steps, not
    # 1000-step episodes) and says so, and where eval.json is.
    eval_dir = tmp_path / "eval_defaults"
    out = run("s3rl-eval", f"checkpoint={run_dir}", f"hydra.run.dir={eval_dir}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    result = json.loads((eval_dir / "eval.json").read_text())
    assert result["episodes"] == 2 and result["episode_lengths"] == [50, 50]
    assert result["settings"] == {
        "episodes": 2, "num_envs": 1, "seed": 100_010, "max_steps": 50,
        "sources": {
            "episodes": "the run's eval.final_episodes",
            "num_envs": "the run's eval.num_envs",
            "seed": "the run's test envs: its seed + 100000",
            "max_steps": "the run's eval.max_steps",
        },
    }
    assert "max_steps=50 (the run's eval.max_steps)" in out.stdout
    assert f"Results: {eval_dir / 'eval.json'}" in out.stdout
    assert "Results: " in (eval_dir / "evaluate.log").read_text()

    eval_dir = tmp_path / "eval"
    out = run(
        "s3rl-eval", f"checkpoint={run_dir}", "episodes=3", "max_steps=30",
        f"hydra.run.dir={eval_dir}", cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    result = json.loads((eval_dir / "eval.json").read_text())
    assert result["episodes"] == 3 and result["length_mean"] == 30.0
    assert "sac_lag SafetyHalfCheetahVelocity-v1 seed 10" in out.stdout
    assert "episodes=3 (given)" in out.stdout and "max_steps=30 (given)" in out.stdout

    # A video, as a new user asks for it: no MUJOCO_GL, no display (the package picks EGL,
    # s3rl_torchrl/_render_backend.py), the default episode.mp4 (imageio-ffmpeg).
    headless = {k: v for k, v in os.environ.items()
                if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    eval_dir = tmp_path / "eval_video"
    out = subprocess.run(
        [str(BIN / "s3rl-eval"), f"checkpoint={run_dir}", "episodes=1", "max_steps=8",
         "video=true", f"hydra.run.dir={eval_dir}"],
        cwd=tmp_path, env=headless, capture_output=True, text=True, timeout=600,
    )
    assert out.returncode == 0, out.stderr
    video = eval_dir / "episode.mp4"
    assert f"Video: {video}" in out.stdout
    import imageio.v2 as imageio

    frames = imageio.mimread(video, format="FFMPEG")
    # The reset frame and one per step.
    assert len(frames) == 9 and frames[0].shape == (256, 256, 3) and frames[0].std() > 0


def test_a_compiled_run_prints_no_third_party_noise(tmp_path):
    # What `make train` printed: tensordict's FutureWarning about a torch._dynamo option, its
    # lock_() warning under torch.compile (torchrl's vmap of the critics' parameters, as in
    # SACLoss) and MuJoCo's settotalmass deprecation (Gymnasium's half_cheetah.xml). None of
    # them now.
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
    # A rejected config writes nothing: no run directory (Hydra made one; the recipe removed
    # it), and in the default place no outputs/<algo>/<task>/seed10/ chain either.
    assert list(tmp_path.iterdir()) == []
    out = run("s3rl-train", *TINY, "algo.update_per_step=-2", cwd=tmp_path)
    assert out.returncode == 2 and list(tmp_path.iterdir()) == []
    # A directory that holds anything else is left as it was: the config is refused before
    # Hydra writes its files or its log there (recipes/launch_checks.py).
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    out = run("s3rl-train", *TINY, "algo.update_per_step=-2", f"hydra.run.dir={mine}",
              cwd=tmp_path)
    assert out.returncode == 2 and (mine / "notes.txt").read_text() == "keep me"
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    out = run("s3rl-train", *TINY, "algo=trpo_lag", cwd=tmp_path)
    assert out.returncode != 0 and "Available options in 'algo'" in out.stderr
    assert "ppo_lag" in out.stderr and "s3rl_ddpg_lag" in out.stderr


def test_eval_rejects_a_corrupt_checkpoint(tmp_path):
    bad = tmp_path / "state.pt"
    bad.write_bytes(b"not a checkpoint")
    out = run("s3rl-eval", f"checkpoint={bad}", f"hydra.run.dir={tmp_path / 'e'}", cwd=tmp_path)
    assert out.returncode == 2 and "is corrupt or not a s3rl-torchrl checkpoint" in out.stderr
    assert not (tmp_path / "e").exists()


def test_eval_without_checkpoint_and_its_help(tmp_path):
    out = run("s3rl-eval", cwd=tmp_path)
    assert out.returncode == 2 and out.stdout == ""
    # One line naming the option, with an example; no traceback, no output directory.
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert out.stderr.startswith("s3rl-eval: missing checkpoint=")
    assert "e.g. s3rl-eval checkpoint=outputs/" in out.stderr
    assert list(tmp_path.iterdir()) == []
    # --help lists s3rl-eval's options, not s3rl-train's config groups (which it rejects).
    out = run("s3rl-eval", "--help", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "Configuration groups" not in out.stdout
    for group in ("algo:", "task:", "experiment:", "critic:", "SafetyHopperVelocity"):
        assert group not in out.stdout
    for option in ("checkpoint", "episodes", "num_envs", "seed", "max_steps", "video_path"):
        assert f"\n{option} " in out.stdout
    out = run("s3rl-eval", "algo=sac", "checkpoint=x", cwd=tmp_path)
    assert out.returncode != 0 and "algo" in out.stderr


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
    # A launcher runs each job in a process of its own, where the recipe's warning filters
    # must be set again: MuJoCo's settotalmass deprecation came back in joblib's workers.
    assert "settotalmass" not in out.stderr + out.stdout


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
