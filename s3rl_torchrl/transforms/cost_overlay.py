"""``CostOverlay``: the unsafe steps of a video, marked on its frames.

A safe-RL video has to show when the agent pays cost. :func:`mark_frame` draws on one RGB
frame a red border when the step that led to it has ``cost > 0``, and a band at the top with
the episode's running cost and reward. :class:`CostOverlay` applies it to every frame of a
``from_pixels`` env (the reset frame: no step, no border, sums 0); ``s3rl-eval video=true``
and the training video (``hooks/video.py``, torchrl's ``VideoRecorder`` after it) both record
its frames.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import torch
from PIL import Image, ImageDraw, ImageFont
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.transforms import Transform

#: The border colour of a frame whose step has cost (pure red, which no task draws all round).
UNSAFE_RGB = (255, 0, 0)
TEXT_RGB = (255, 255, 255)
BAND_RGB = (0, 0, 0)


def border_width(height: int, width: int) -> int:
    """The red border's width in pixels: 1/32 of the shorter side, at least 2."""
    return max(2, min(height, width) // 32)


@cache
def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    # Pillow's own font (>= 10.1 scales it): no font file or new package needed.
    return ImageFont.load_default(size=size)


def overlay_text(episode_cost: float, episode_reward: float) -> str:
    """The band's text: the episode's running cost and reward."""
    return f"cost {episode_cost:g}  reward {episode_reward:.1f}"


def mark_frame(
    frame: np.ndarray, cost: float, episode_cost: float, episode_reward: float
) -> np.ndarray:
    """A copy of ``frame`` (``[H, W, 3]`` uint8) with the running ``episode_cost`` and
    ``episode_reward`` in a band at its top and, if the step's ``cost > 0``, a red border."""
    if frame.ndim != 3 or frame.shape[-1] != 3 or frame.dtype != np.uint8:
        raise ValueError(f"mark_frame takes an [H, W, 3] uint8 frame, got {frame.dtype} "
                         f"{tuple(frame.shape)}.")
    height, width = frame.shape[:2]
    border = border_width(height, width)
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    font_size = max(8, height // 18)
    band = font_size + 4
    draw.rectangle((border, border, width - 1 - border, border + band - 1), fill=BAND_RGB)
    draw.text(
        (border + 2, border + 1),
        overlay_text(episode_cost, episode_reward),
        fill=TEXT_RGB,
        font=_font(font_size),
    )
    out = np.asarray(image).copy()
    if cost > 0:
        out[:border], out[-border:] = UNSAFE_RGB, UNSAFE_RGB
        out[:, :border], out[:, -border:] = UNSAFE_RGB, UNSAFE_RGB
    return out


def is_marked(frame: np.ndarray) -> bool:
    """Whether ``frame`` carries :func:`mark_frame`'s red border (every border pixel red)."""
    border = border_width(*frame.shape[:2])
    edges = (frame[:border], frame[-border:], frame[:, :border], frame[:, -border:])
    return all(bool((edge == UNSAFE_RGB).all()) for edge in edges)


class CostOverlay(Transform):
    """Mark each frame in ``pixels_key`` with :func:`mark_frame`: the step's ``cost_key`` and
    the running sums in ``episode_cost_key`` and ``episode_reward_key`` (what ``make_env``'s
    ``EpisodeSum`` and ``RewardSum`` write; append this transform after them).

    Frames may carry batch dimensions (``[..., H, W, 3]``); each is marked on its own."""

    def __init__(
        self,
        pixels_key: NestedKey = "pixels",
        cost_key: NestedKey = "cost",
        episode_cost_key: NestedKey = "episode_cost",
        episode_reward_key: NestedKey = "episode_reward",
    ):
        super().__init__(in_keys=[pixels_key], out_keys=[pixels_key])
        self.pixels_key, self.cost_key = pixels_key, cost_key
        self.episode_cost_key, self.episode_reward_key = episode_cost_key, episode_reward_key

    def _mark(self, data: TensorDictBase, cost: torch.Tensor | None) -> TensorDictBase:
        pixels = data.get(self.pixels_key)
        frames = pixels.reshape(-1, *pixels.shape[-3:]).cpu().numpy()
        count = frames.shape[0]

        def per_frame(key: NestedKey | None, value: torch.Tensor | None = None) -> np.ndarray:
            if value is None:
                value = data.get(key, None)
            if value is None:
                return np.zeros(count)
            return value.reshape(count, -1).sum(-1).float().cpu().numpy()

        costs = per_frame(None, cost) if cost is not None else np.zeros(count)
        episode_costs = per_frame(self.episode_cost_key)
        episode_rewards = per_frame(self.episode_reward_key)
        marked = np.stack(
            [
                mark_frame(frame, c, ec, er)
                for frame, c, ec, er in zip(frames, costs, episode_costs, episode_rewards)
            ]
        )
        data.set(self.pixels_key, torch.as_tensor(marked, device=pixels.device).reshape(pixels.shape))
        return data

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._mark(next_tensordict, next_tensordict.get(self.cost_key))

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # The first frame of an episode follows no step: no cost, and the sums start at 0.
        return self._mark(tensordict_reset, None)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Mark the frames of stored steps (``("next", pixels)``, read with ``("next", cost)``)."""
        self._mark(tensordict.get("next"), tensordict.get(("next", self.cost_key)))
        return tensordict
