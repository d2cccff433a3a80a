"""``EpisodeSum``: torchrl's ``RewardSum`` for any per-step scalar, e.g. the cost."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import expand_as_right
from torchrl.data import Composite
from torchrl.envs.transforms import RewardSum
from torchrl.envs.transforms.utils import _get_reset  # private; torchrl is pinned to 0.14.x


class EpisodeSum(RewardSum):
    """Running per-episode sum of step entries, like ``RewardSum``.

    ``RewardSum`` only accepts keys of the reward spec; the cost is read from Gymnasium's
    ``info`` and therefore declared in the observation spec. This subclass looks keys up in
    both, so ``EpisodeSum(in_keys=["cost"], out_keys=["episode_cost"])`` tracks the episode
    cost the Lagrangian controller needs, with ``RewardSum``'s reset semantics.
    """

    def _step_spec(self) -> Composite:
        parent = self.parent
        return Composite(
            **parent.full_reward_spec, **parent.full_observation_spec, shape=parent.batch_size
        )

    def _generate_episode_reward_spec(self) -> Composite:
        spec = self._step_spec()
        out = Composite()
        for in_key, out_key in zip(self.in_keys, self.out_keys, strict=True):
            if in_key not in spec.keys(True, True):
                raise ValueError(
                    f"EpisodeSum: {in_key!r} is in neither the reward nor the observation spec."
                )
            out[out_key] = spec[in_key].clone()
        return out

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        for in_key, reset_key, out_key in zip(
            self.in_keys, self.reset_keys, self.out_keys, strict=True
        ):
            value = tensordict.get(out_key, default=None)
            if value is None:
                value = self._step_spec()[in_key].zero()
            else:
                reset = _get_reset(reset_key, tensordict)
                value = torch.where(expand_as_right(~reset, value), value, 0.0)
            tensordict_reset.set(out_key, value)
        return tensordict_reset
