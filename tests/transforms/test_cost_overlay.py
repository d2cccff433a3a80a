"""The unsafe-step marking of videos (transforms/cost_overlay.py, envs/video.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from s3rl_torchrl.transforms import is_marked, mark_frame
from s3rl_torchrl.transforms.cost_overlay import UNSAFE_RGB, border_width


def test_mark_frame_draws_the_border_exactly_when_the_step_costs():
    frame = np.full((64, 80, 3), 90, dtype=np.uint8)
    safe, unsafe = mark_frame(frame, 0.0, 0.0, 1.0), mark_frame(frame, 1.0, 1.0, 1.0)
    assert (frame == 90).all()  # the input is not changed
    assert safe.shape == unsafe.shape == frame.shape and unsafe.dtype == np.uint8
    b = border_width(64, 80)
    assert b == 2
    assert (unsafe[:b] == UNSAFE_RGB).all() and (unsafe[:, -b:] == UNSAFE_RGB).all()
    assert not (safe[:b] == UNSAFE_RGB).all(axis=-1).any()
    assert is_marked(unsafe) and not is_marked(safe) and not is_marked(frame)
    # Below the band and inside the border, the picture is untouched.
    assert (unsafe[30:-b, b:-b] == 90).all() and (safe[30:, :] == 90).all()


def test_the_band_shows_the_running_cost_and_reward():
    frame = np.zeros((64, 64, 3), dtype=np.uint8)
    a, b = mark_frame(frame, 0.0, 3.0, 10.0), mark_frame(frame, 0.0, 4.0, 10.0)
    band = slice(2, 2 + max(8, 64 // 18) + 4)
    assert (a[band] != b[band]).any()  # another cost, another text
    assert (mark_frame(frame, 0.0, 3.0, 10.0) == a).all()  # deterministic


class ConstantAction:
    """Plays one action, so that the tasks below reach their unsafe states in a few steps."""

    def __init__(self, action, shape):
        self.action, self.shape = torch.as_tensor(action, dtype=torch.float32), shape

    def __call__(self, td):
        td["action"] = self.action.expand(self.shape).clone()
        return td


# family: (task, seed, steps, action) whose rollout has steps with and without cost (the
# reset frame has none). Swimmer-v0's speed limit (0.048) is exceeded from its first step.
ROLLOUTS = {
    "velocity": ("SafetySwimmerVelocity-v0", 0, 20, 1.0),
    "circle": ("SafetyCarCircle1-v0", 0, 36, 1.0),
    "goal": ("SafetyPointGoal1-v0", 1, 44, 1.0),
    "bullet_run": ("SafetyBallRun-v0", 0, 16, 1.0),
    "bullet_circle": ("SafetyBallCircle-v0", 0, 14, 1.0),
}


@pytest.mark.parametrize("family", list(ROLLOUTS))
def test_marked_frames_are_exactly_the_steps_with_cost(family):
    from s3rl_torchrl.envs.video import make_video_env

    task, seed, steps, action = ROLLOUTS[family]
    env = make_video_env(task, seed=seed, size=48)
    try:
        rollout = env.rollout(
            steps, ConstantAction(action, env.action_spec.shape), break_when_any_done=False
        )
    finally:
        env.close()
    # The reference: the cost the env reported for each step (info["cost"]), not the overlay.
    costs = rollout["next", "cost"].squeeze(-1) > 0
    assert costs.any(), f"{task}: no step with cost, the check would be empty"
    marked = torch.tensor([is_marked(f) for f in rollout["next", "pixels"].numpy()])
    assert torch.equal(marked, costs)
    assert not is_marked(rollout["pixels"][0].numpy())  # the reset frame
    frames = rollout["next", "pixels"].float()
    assert frames.std() > 0  # a rendered scene, not a blank frame
