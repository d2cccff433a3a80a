"""Exact env snapshots: a restored env steps exactly as the one it was taken from."""

from __future__ import annotations

import io

import pytest
import torch

from s3rl_torchrl.envs import make_env
from s3rl_torchrl.envs.state import env_snapshot, exact_restore_unsupported, restore_env


def _steps(env, td, actions):
    outs = []
    for action in actions:
        td["action"] = action.clone()
        out, td = env.step_and_maybe_reset(td)
        outs.append(out["next"].clone())
    return outs, td


@pytest.mark.parametrize(
    "task, steps",
    [
        # Hopper falls within ~20 random steps: resets inside both stretches.
        ("SafetyHopperVelocity-v1", 60),
        ("SafetyHumanoidVelocity-v1", 60),
        ("SafetyPointCircle1-v0", 60),
        # 1000-step episodes: the first stretch ends past the time limit, so the restored env
        # has drawn a new layout and goals (model fields and the layout generator).
        ("SafetyPointGoal1-v0", 1010),
    ],
)
def test_restored_env_steps_exactly_as_the_original(task, steps):
    original = make_env(task, num_envs=2, seed=1)
    torch.manual_seed(0)
    td = original.reset()
    _, td = _steps(original, td, [original.action_spec.rand() for _ in range(steps)])
    buffer = io.BytesIO()
    torch.save(env_snapshot(original), buffer)
    buffer.seek(0)
    snapshot = torch.load(buffer, weights_only=True)  # what a checkpoint gives back

    restored = make_env(task, num_envs=2, seed=99)  # another seed: everything must come back
    restored.reset()
    restore_env(restored, snapshot)
    actions = [original.action_spec.rand() for _ in range(40)]
    expected, _ = _steps(original, td.clone(), actions)
    got, _ = _steps(restored, td.clone(), actions)
    for a, b in zip(expected, got, strict=True):
        assert (a == b).all()


def test_bullet_and_process_batching_have_no_snapshot():
    pytest.importorskip("bullet_safety_gym")
    bullet = make_env("SafetyBallRun-v0", num_envs=2, seed=0)
    assert exact_restore_unsupported(bullet).startswith("SafetyBallRun-v0 is not a MuJoCo env")
    assert "pybullet" in exact_restore_unsupported(bullet)
    assert env_snapshot(bullet) is None


def test_snapshot_of_another_size_is_refused():
    snapshot = env_snapshot(make_env("SafetyHopperVelocity-v1", num_envs=2, seed=0))
    with pytest.raises(ValueError, match="2 copies.*3"):
        restore_env(make_env("SafetyHopperVelocity-v1", num_envs=3, seed=0), snapshot)


def test_a_snapshot_of_another_mujoco_release_is_refused_naming_both(monkeypatch):
    from s3rl_torchrl.envs import state

    snapshot = env_snapshot(make_env("SafetyHopperVelocity-v1", num_envs=1, seed=0))
    assert snapshot["mujoco"] == state.MUJOCO_VERSION
    snapshot["mujoco"] = "3.3.7"
    with pytest.raises(state.SnapshotMismatch, match=(
        rf"written by MuJoCo 3.3.7 and this is MuJoCo {state.MUJOCO_VERSION}.*mujoco==3.3.7"
    )):
        restore_env(make_env("SafetyHopperVelocity-v1", num_envs=1, seed=0), snapshot)


def test_simulator_bytes_mujoco_cannot_read_are_a_clear_error():
    # A snapshot written before releases were recorded, by a release whose MjData this one
    # cannot read (MuJoCo's own refusal is "Invalid serialized mjModel"): here, cut bytes.
    from s3rl_torchrl.envs import state

    snapshot = env_snapshot(make_env("SafetyHopperVelocity-v1", num_envs=1, seed=0))
    del snapshot["mujoco"]
    snapshot["copies"][0]["data"] = snapshot["copies"][0]["data"][:64].clone()
    with pytest.raises(state.SnapshotMismatch, match="cannot read the snapshot's simulator state"):
        restore_env(make_env("SafetyHopperVelocity-v1", num_envs=1, seed=0), snapshot)
