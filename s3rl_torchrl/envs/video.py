"""``make_video_env``: a task that renders its frames, unsafe steps marked, and writing them.

What a recorded step costs (docs/video.md): on a CPU-only machine MuJoCo renders through
Mesa's software OpenGL, where its default shadow map (4096 x 4096) and 4x multisampling took
~220 ms of a HalfCheetah frame of 256 x 256 pixels; with a 1024 shadow map and no multisampling
it took ~50 ms, with the same picture at this size. :func:`make_video_env` renders so. Bullet
tasks render on PyBullet's CPU renderer (``envs/bullet.py``, :class:`RgbArrayRender`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from torchrl.envs import TransformedEnv

from s3rl_torchrl._render_backend import require_render_backend
from s3rl_torchrl.envs.make import make_env
from s3rl_torchrl.envs.registry import get_task
from s3rl_torchrl.transforms import CostOverlay

#: Frame size of a recorded video (pixels, square): the overlay's text stays legible.
VIDEO_SIZE = 256
#: MuJoCo's offscreen quality for videos (``model.vis.quality``; see the module docstring).
MUJOCO_SHADOW_SIZE = 1024
MUJOCO_OFFSCREEN_SAMPLES = 0
#: Frames per second of written videos: MuJoCo's and Bullet's tasks step 20-50 times per
#: simulated second; 30 plays them near real time and keeps the player's rate standard.
VIDEO_FPS = 30


def _gym_envs(env: TransformedEnv) -> list[Any]:
    """The Gymnasium envs under ``env`` (one, or the copies of a vector env)."""
    gym_env = env.base_env._env
    return list(getattr(gym_env, "envs", [gym_env]))


def make_video_env(task: str, seed: int | None = None, size: int = VIDEO_SIZE) -> TransformedEnv:
    """One copy of ``task`` (``make_env``: costs, running sums) whose ``"pixels"`` are
    ``size`` x ``size`` rendered frames marked by :class:`CostOverlay`.

    MuJoCo tasks check the offscreen backend first (one line naming the package to install,
    :func:`~s3rl_torchrl._render_backend.require_render_backend`) and render with
    :data:`MUJOCO_SHADOW_SIZE` and :data:`MUJOCO_OFFSCREEN_SAMPLES`.
    """
    family = get_task(task).family
    if family != "bullet":
        require_render_backend()
    env = make_env(
        task, seed=seed, from_pixels=True, pixels_only=False, width=size, height=size
    )
    if family != "bullet":
        for gym_env in _gym_envs(env):
            quality = gym_env.unwrapped.model.vis.quality
            quality.shadowsize = MUJOCO_SHADOW_SIZE
            quality.offsamples = MUJOCO_OFFSCREEN_SAMPLES
            # MuJoCo reads them when a renderer's context is made, and torchrl rendered a
            # first frame already (to size "pixels"): drop Gymnasium's viewer, so that the
            # next frame makes a new context with them.
            renderer = gym_env.unwrapped.mujoco_renderer
            renderer.close()
            renderer._viewers.clear()
            renderer.viewer = None
    env.append_transform(CostOverlay())
    return env


class VideoWriter:
    """Writes frames one at a time to ``path``, the format from its suffix: ``.mp4``
    (imageio-ffmpeg's bundled FFmpeg, H.264) or ``.gif`` (Pillow). Streaming keeps memory
    at one frame, where a 1000-step rollout of 256 x 256 frames would hold 200 MB."""

    def __init__(self, path: str | Path, fps: int = VIDEO_FPS):
        import imageio.v2 as imageio

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.suffix == ".gif":
            self._writer = imageio.get_writer(self.path, mode="I", duration=1000 / fps, loop=0)
        else:
            # macro_block_size=1: no resizing warning for sizes that are not multiples of 16.
            self._writer = imageio.get_writer(self.path, fps=fps, macro_block_size=1)
        self.frames = 0

    def append(self, frame: np.ndarray) -> None:
        self._writer.append_data(np.asarray(frame, dtype=np.uint8))
        self.frames += 1

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
