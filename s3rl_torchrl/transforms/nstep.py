"""n-step returns for reward *and* cost, with bootstrapping masked on termination only.

torchrl's :class:`~torchrl.envs.transforms.MultiStepTransform` (0.14.1) has three problems for a
safe-RL replay buffer, found while checking it against a hand computation:

1. The done keys (``done``, ``terminated``, ``truncated``) are left at step ``t`` while the
   next observation moves to ``t + k``. When an episode *terminates* at ``t + 1`` (n = 2), the
   transition of step ``t`` keeps ``terminated = False`` and its target bootstraps from the
   terminal observation, which it must not.
2. With several reward keys (``["reward", "cost"]``), every original value is renamed to the same
   ``("next", "original_reward")`` entry, so the original reward is overwritten by the cost.
3. Every other ``next`` entry is moved to ``t + k``, including labels that describe step ``t``
   itself (S3RL's ``("next", "safe")``).

:class:`NStepTransform` keeps torchrl's buffering (so it is a drop-in replay-buffer transform) and
replaces the computation with :func:`nstep_transition`, which fixes the three points:

- the window of step ``t`` is ``t .. t + k`` with ``k = min(n - 1, steps to the episode end)``;
  an episode ends at ``done`` (termination **or** truncation);
- each reward key becomes ``sum_{j <= k} gamma^j r_{t+j}``; its one-step value is kept as
  ``("next", "<key>_orig")``;
- every ``next`` entry, done flags included, is taken at ``t + k``, except ``keep_keys``;
- ``steps_to_next_obs = k + 1`` is written at the root, where torchrl's TD(0) estimator (and
  :class:`~s3rl_torchrl.objectives.SACLagLoss`) read it to discount the bootstrap by
  ``gamma ** steps_to_next_obs``.

A truncated window (time limit) therefore bootstraps from the real last observation with
``gamma ** (k + 1)``, and a terminated one does not bootstrap at all.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs.transforms import MultiStepTransform

__all__ = ["NStepTransform", "make_nstep_transform", "nstep_transition"]

_DONE_KEYS = ("done", "terminated", "truncated")


def _as_next_key(key: NestedKey) -> tuple[str, ...]:
    return ("next", *key) if isinstance(key, tuple) else ("next", key)


def _orig_key(key: NestedKey, suffix: str) -> tuple[str, ...]:
    key = key if isinstance(key, tuple) else (key,)
    return ("next", *key[:-1], key[-1] + suffix)


def _check_n_gamma(n_steps: int, gamma: float) -> None:
    if isinstance(n_steps, bool) or not isinstance(n_steps, int) or n_steps < 1:
        raise ValueError(f"n_steps must be an integer >= 1, got {n_steps!r}.")
    if not 0.0 < float(gamma) <= 1.0:
        raise ValueError(f"gamma must be in (0, 1], got {gamma!r}.")


def nstep_transition(
    tensordict: TensorDictBase,
    n_steps: int,
    gamma: float,
    *,
    reward_keys: Sequence[NestedKey] = ("reward", "cost"),
    done_key: NestedKey = "done",
    keep_keys: Sequence[NestedKey] = ("safe",),
    orig_suffix: str = "_orig",
) -> TensorDictBase:
    """Turn one-step transitions ``[*batch, T]`` (time last) into n-step transitions.

    Returns a new tensordict (the input is not modified) of the same shape. See the module
    docstring for the exact semantics. The last ``n_steps - 1`` steps of the time dimension see a
    shortened window unless an episode ends inside it: :class:`NStepTransform` holds them back
    until the next ``extend`` supplies their future.

    Args:
        tensordict: transitions with ``("next", key)`` entries for every reward key and
            ``("next", done_key)``; the last batch dimension is time.
        n_steps: window length ``n`` (1 leaves rewards unchanged and only adds the bookkeeping).
        gamma: discount used inside the window (must equal the loss's gamma).
        reward_keys: ``next`` entries that are discounted and summed (reward and costs).
        done_key: ``next`` entry that ends an episode (``done`` = terminated or truncated).
        keep_keys: ``next`` entries that describe step ``t`` itself and stay there.
        orig_suffix: suffix of the entries keeping the one-step reward values.
    """
    _check_n_gamma(n_steps, gamma)
    if tensordict.ndim < 1:
        raise ValueError("nstep_transition needs a time dimension (the last batch dimension).")
    next_td = tensordict.get("next")
    *batch, T = tensordict.batch_size
    done = next_td.get(done_key, None)
    if done is None:
        raise KeyError(
            f"nstep_transition needs ('next', {done_key!r}); keys: {list(next_td.keys())}."
        )
    if done.shape == tensordict.batch_size + (1,):
        done = done.squeeze(-1)
    if done.shape != tensordict.batch_size:
        raise ValueError(
            f"('next', {done_key!r}) must have shape {tuple(tensordict.batch_size)} "
            "(+ a trailing 1), "
            f"got {tuple(done.shape)}."
        )
    done = done.bool()
    time_dim = tensordict.ndim - 1
    device = done.device
    t = torch.arange(T, device=device)

    rewards = {}
    for key in reward_keys:
        value = next_td.get(key, None)
        if value is None:
            raise KeyError(
                f"reward key ('next', {key!r}) not found; keys: {list(next_td.keys(True))}."
            )
        rewards[key] = value
    sums = {key: torch.zeros_like(value) for key, value in rewards.items()}
    last = torch.zeros(tensordict.batch_size, dtype=torch.long, device=device)
    alive = torch.ones(tensordict.batch_size, dtype=torch.bool, device=device)
    for k in range(n_steps):
        idx = (t + k).clamp_max(T - 1)
        valid = alive & (t + k < T)
        for key, value in rewards.items():
            shifted = value.index_select(time_dim, idx)
            mask = valid.reshape(valid.shape + (1,) * (value.ndim - valid.ndim))
            sums[key] = sums[key] + (gamma**k) * torch.where(mask, shifted, 0)
        last = torch.where(valid, k, last)
        # The window stops after the step that ends the episode (terminated or truncated).
        alive = valid & ~done.index_select(time_dim, idx)

    out = tensordict.clone(False)
    present_keep = [key for key in keep_keys if key in next_td.keys(True)]
    moved = next_td.exclude(*reward_keys, *present_keep)
    gather_idx = t.expand(*batch, T) + last
    out_next = out.get("next")
    out_next.update(moved.gather(time_dim, gather_idx))
    for key, value in rewards.items():
        out.set(_orig_key(key, orig_suffix), value)
        out.set(_as_next_key(key), sums[key])
    # Same layout as torchrl's MultiStepTransform ([*batch, T]), which its value estimators read.
    out.set("steps_to_next_obs", last + 1)
    return out


class NStepTransform(MultiStepTransform):
    """Replay-buffer transform giving n-step reward/cost transitions (see module docstring).

    A drop-in replacement for torchrl's ``MultiStepTransform`` that bootstraps correctly around
    terminations, keeps one ``<key>_orig`` entry per reward key and leaves ``keep_keys`` at step
    ``t``. Like torchrl's, it must see consecutive batches of the same env copies (a collector's
    output, time last) and holds back the last ``n_steps`` frames of each batch until the next
    ``extend``.

    With ``flatten=True`` (default) the output is flattened to one transition per row, which
    is what a 1-D replay-buffer storage (``LazyTensorStorage(size)``) holds; torchrl's transform
    keeps ``[num_envs, time]``, which needs a 2-D storage whose time length matches every batch.
    """

    def __init__(
        self,
        n_steps: int,
        gamma: float,
        *,
        reward_keys: Sequence[NestedKey] = ("reward", "cost"),
        done_key: NestedKey = "done",
        keep_keys: Sequence[NestedKey] = ("safe",),
        orig_suffix: str = "_orig",
        flatten: bool = True,
    ):
        _check_n_gamma(n_steps, gamma)
        super().__init__(
            n_steps,
            gamma,
            reward_keys=list(reward_keys),
            done_key=done_key,
            done_keys=list(_DONE_KEYS),
        )
        self.keep_keys = tuple(keep_keys)
        self.orig_suffix = orig_suffix
        self.flatten = bool(flatten)

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase | None:
        if not self._validated:
            self._validate()
        if tensordict.ndim < 1:
            raise ValueError(
                "NStepTransform needs a time dimension (a collector's batch, [num_envs, time] "
                f"or [time]); got batch size {tuple(tensordict.batch_size)}."
            )
        total = self._append_tensordict(tensordict)
        _check_consecutive(total)
        if total.shape[-1] <= self.n_steps:
            return None
        out = nstep_transition(
            total,
            self.n_steps,
            self.gamma,
            reward_keys=self.reward_keys,
            done_key=self.done_key,
            keep_keys=self.keep_keys,
            orig_suffix=self.orig_suffix,
        )
        out = out[..., : -self.n_steps]
        return out.reshape(-1) if self.flatten else out


    @property
    def held_frames(self) -> TensorDictBase | None:
        """The last ``n_steps`` frames of each env copy, held back until the next batch (the
        windows of their steps end in it); ``None`` before the first batch. A checkpoint keeps
        them, so that a resumed run stores the same transitions as an uninterrupted one."""
        return self._buffer

    def load_held_frames(self, frames: TensorDictBase | None) -> None:
        """Restore :attr:`held_frames` (from a checkpoint)."""
        self._buffer = None if frames is None else frames.clone()

    def end_held_episodes(self) -> None:
        """End every held episode at its last held step, as a time limit ends one
        (``("next", "done")`` and ``("next", "truncated")`` set, ``terminated`` untouched):
        for envs that restart their episodes before the next batch, e.g. a resume that could not
        restore them. The held steps' windows then stop there and bootstrap from the last
        observation, instead of running into another episode's steps."""
        if self._buffer is None:
            return
        last = (slice(None),) * (self._buffer.ndim - 1) + (-1,)
        for key in (("next", "done"), ("next", "truncated")):
            flags = self._buffer.get(key, None)
            if flags is not None:
                flags[last] = True


def _check_consecutive(frames: TensorDictBase) -> None:
    """Refuse frames whose time dimension is not one env copy's consecutive steps, e.g. a
    flattened ``[num_envs * time]`` batch, whose windows would silently cross copies.

    Read from the root ``step_count`` (torchrl's ``StepCounter``, which ``make_env`` adds):
    within an episode it grows by one per step; after a step whose ``("next", "done")`` is set
    it restarts. Frames without a ``step_count`` are not checked."""
    steps = frames.get("step_count", None)
    done = frames.get(("next", "done"), None)
    if steps is None or done is None or frames.shape[-1] < 2:
        return
    steps = steps.reshape(frames.shape)
    done = done.reshape(frames.shape)
    broken = (steps[..., 1:] != steps[..., :-1] + 1) & ~done[..., :-1]
    if broken.any():
        raise ValueError(
            "NStepTransform: the time dimension (the last batch dimension) does not hold "
            "consecutive steps of one env copy (step_count jumps without an episode end), so "
            "n-step windows would mix copies. Extend the buffer with the collector's batch as "
            "it comes, [num_envs, time] unflattened: the transform flattens its output itself."
        )


def make_nstep_transform(
    n_steps: int,
    gamma: float,
    cost_key: NestedKey = "cost",
    *,
    reward_key: NestedKey = "reward",
    keep_keys: Sequence[NestedKey] = ("safe",),
    flatten: bool = True,
) -> NStepTransform:
    """The n-step replay-buffer transform :class:`~s3rl_torchrl.objectives.SACLagLoss` expects.

    Discounts and sums ``("next", reward_key)`` and ``("next", cost_key)`` over ``n_steps`` with
    ``gamma`` (use the loss's gamma), moves the next observation and the done flags to the end
    of the window, and writes ``steps_to_next_obs``. Use it as ``ReplayBuffer(
    storage=LazyTensorStorage(size), transform=make_nstep_transform(2, 0.99))`` and ``extend``
    with a collector's batches (``[num_envs, time]``, unflattened: the transform flattens).
    """
    return NStepTransform(
        n_steps,
        gamma,
        reward_keys=(reward_key, cost_key),
        keep_keys=keep_keys,
        flatten=flatten,
    )
