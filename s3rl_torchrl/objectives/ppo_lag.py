"""PPO-Lagrangian loss (FSRL's ``PPOLagrangian``) as a torchrl ``ClipPPOLoss`` subclass.

A reward value network ``V_r`` (``ClipPPOLoss``'s critic) and a cost value network ``V_c``,
each with its own GAE (torchrl's :class:`~torchrl.objectives.value.GAE`, run once on the reward
with ``V_r`` and once on ``("next", "cost")`` with ``V_c``), give the advantages ``A_r``,
``A_c`` and the value targets ``R_r = A_r + V_r``, ``R_c = A_c + V_c``. With
``rho = pi(a|s) / pi_old(a|s)``, advantages standardised per minibatch
(``normalize_advantage``) and a multiplier ``lambda >= 0``, the policy loss is

- ``cost_surrogate="unclipped"`` (FSRL, default)::

      L_pi = [-mean(min(rho A_r, clip(rho, 1 - eps, 1 + eps) A_r)) + lambda mean(rho A_c)]
             / (1 + lambda)

- ``cost_surrogate="clipped"`` (OmniSafe's PPOLag: the clipped surrogate of one advantage)::

      A = (A_r - lambda A_c) / (1 + lambda)
      L_pi = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A))

(``/ (1 + lambda)`` only with ``rescaling``), and the critic losses are
``critic_coeff * mean((V_r - R_r)^2)`` and ``critic_coeff * mean((V_c - R_c)^2)``.
FSRL: ``fsrl/policy/ppo_lag.py`` (``policy_loss``, ``critics_loss``, ``learn``) with
``fsrl/policy/lagrangian_base.py`` (``safety_loss``) and the defaults of
``fsrl/config/ppol_cfg.py``; OmniSafe: ``omnisafe/algorithms/on_policy/naive_lagrange/
ppo_lag.py`` (``_compute_adv_surrogate``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict import TensorDictBase, TensorDictParams
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, dispatch
from tensordict.utils import NestedKey
from torch import Tensor
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.ppo import _broadcast_advantage_to_log_weight, _clip_value_loss
from torchrl.objectives.utils import ValueEstimators, _cache_values, distance_loss
from torchrl.objectives.value import GAE

from s3rl_torchrl.objectives._common import next_key as _next
from s3rl_torchrl.objectives._lagrangian_buffer import LagrangianBufferMixin

__all__ = ["COST_SURROGATES", "PPOLagLoss"]

#: The cost term of the policy loss: FSRL's unclipped one or OmniSafe's clipped surrogate.
COST_SURROGATES = ("unclipped", "clipped")


class PPOLagLoss(LagrangianBufferMixin, ClipPPOLoss):
    r"""PPO with a Lagrangian cost penalty (FSRL's PPO-Lag), TensorDict-native.

    A subclass of :class:`torchrl.objectives.ClipPPOLoss` that adds a cost value network, a
    second GAE for the cost, the cost critic loss and the penalised policy loss (module
    docstring). One cost signal, read at ``("next", "cost")`` (shape ``[*B]`` or ``[*B, 1]``).
    ``lagrangian`` is a buffer of shape ``[1]``, set once per collect, e.g.
    ``loss.set_lagrangian(controller.update(mean_episode_cost))``.

    With ``lagrangian = 0`` the policy, entropy and reward critic losses are ``ClipPPOLoss``'s
    on the same networks and batch.

    Compute both advantages once per collected batch (before splitting it into minibatches)
    with :meth:`compute_advantages`; the forward computes them itself when they are missing.

    Args:
        actor_network: stochastic actor (e.g. :func:`~s3rl_torchrl.modules.build_s3rl_actor`).
        critic_network: reward value network ``observation -> "state_value"`` (``[..., 1]``).
        cost_critic_network: cost value network ``observation -> "state_cost_value"``
            (``[..., 1]``).

    Keyword Args:
        cost_surrogate: ``"unclipped"`` (FSRL: ``lambda rho A_c`` added to the clipped reward
            surrogate) or ``"clipped"`` (OmniSafe: clipped surrogate of
            ``A_r - lambda A_c``).
        rescaling: divide the policy loss by ``1 + lambda`` (FSRL, OmniSafe: ``True``).
        lagrangian_init: initial ``lagrangian`` (>= 0).
        clip_epsilon: PPO clip (FSRL ``eps_clip = 0.2``).
        entropy_bonus: FSRL has none (``False``).
        critic_coeff: weight of both critic losses (FSRL ``vf_coef = 0.25``).
        loss_critic_type: FSRL: ``"l2"`` (squared error).
        normalize_advantage: standardise ``A_r`` and ``A_c`` per minibatch (FSRL ``norm_adv``).
        Other keyword arguments go to ``ClipPPOLoss`` (``advantage_norm`` is not supported).

    Keys (``loss.set_keys(...)``): those of ``ClipPPOLoss`` plus ``cost`` (read at
    ``("next", cost)``), ``cost_value`` (the cost critic's output), ``cost_advantage`` and
    ``cost_value_target``.

    The forward returns ``ClipPPOLoss``'s entries (``loss_objective`` is the penalised policy
    loss) plus ``loss_cost_critic`` and ``lagrangian``; minimise the sum of the ``loss_*``
    entries. Set ``gamma`` and the GAE ``lmbda`` with ``loss.make_value_estimator(gamma=...,
    lmbda=...)``: the cost GAE uses the same values.
    """

    @dataclass
    class _AcceptedKeys(ClipPPOLoss._AcceptedKeys):
        """Tensordict keys of :class:`PPOLagLoss`: ``ClipPPOLoss``'s plus the cost ones.

        Attributes:
            cost: cost entry, read at ``("next", cost)``.
            cost_value: output key of the cost value network.
            cost_advantage: where the cost GAE writes the cost advantage.
            cost_value_target: where the cost GAE writes the cost value target.
        """

        cost: NestedKey = "cost"
        cost_value: NestedKey = "state_cost_value"
        cost_advantage: NestedKey = "cost_advantage"
        cost_value_target: NestedKey = "cost_value_target"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    SUPPORTED_VALUE_ESTIMATORS = (ValueEstimators.GAE,)
    _schedulable_buffers = frozenset(ClipPPOLoss._schedulable_buffers | {"lagrangian"})

    cost_critic_network: TensorDictModule
    cost_critic_network_params: TensorDictParams
    target_cost_critic_network_params: TensorDictParams

    def __init__(
        self,
        actor_network: ProbabilisticTensorDictSequential,
        critic_network: TensorDictModule,
        cost_critic_network: TensorDictModule,
        *,
        cost_surrogate: Literal["unclipped", "clipped"] = "unclipped",
        rescaling: bool = True,
        lagrangian_init: float | Sequence[float] | Tensor = 0.0,
        clip_epsilon: float = 0.2,
        entropy_bonus: bool = False,
        critic_coeff: float = 0.25,
        loss_critic_type: str = "l2",
        normalize_advantage: bool = True,
        **kwargs,
    ) -> None:
        if cost_surrogate not in COST_SURROGATES:
            raise ValueError(
                f"Unknown cost_surrogate {cost_surrogate!r}; valid choices are "
                f"{', '.join(map(repr, COST_SURROGATES))}."
            )
        if cost_critic_network is None or critic_network is None:
            raise ValueError("PPOLagLoss needs a critic_network and a cost_critic_network.")
        if kwargs.get("advantage_norm") is not None:
            raise ValueError("PPOLagLoss does not support advantage_norm; use normalize_advantage.")
        if kwargs.get("functional", True) is False:
            raise ValueError("PPOLagLoss needs functional=True (the default).")
        if not critic_coeff > 0:
            raise ValueError(f"critic_coeff must be > 0, got {critic_coeff!r}.")
        super().__init__(
            actor_network,
            critic_network,
            clip_epsilon=clip_epsilon,
            entropy_bonus=entropy_bonus,
            critic_coeff=critic_coeff,
            loss_critic_type=loss_critic_type,
            normalize_advantage=normalize_advantage,
            **kwargs,
        )
        self.convert_to_functional(
            cost_critic_network,
            "cost_critic_network",
            compare_against=(
                list(actor_network.parameters()) if kwargs.get("separate_losses") else None
            ),
        )
        self._set_in_keys()
        self.num_costs = 1
        self.cost_surrogate = cost_surrogate
        self.rescaling = bool(rescaling)
        self._init_lagrangian(lagrangian_init, device=self.clip_epsilon.device)
        self._cost_value_estimator = None
        self._last_log_ratio = None
        self._last_cost_advantage = None

    # ------------------------------------------------------------------ keys and estimators
    def _set_in_keys(self):
        super()._set_in_keys()
        cost_critic = self.__dict__.get("cost_critic_network")
        if cost_critic is None:  # ClipPPOLoss sets its keys before the cost critic exists
            return
        keys = set(self._in_keys) | set(cost_critic.in_keys)
        keys.add(_next(self.tensor_keys.cost))
        self._in_keys = list(keys)

    @property
    def out_keys(self):
        if self._out_keys is None:
            keys = list(ClipPPOLoss.out_keys.fget(self))
            self._out_keys = [*keys, "loss_cost_critic", "lagrangian"]
        return self._out_keys

    @out_keys.setter
    def out_keys(self, values):
        self._out_keys = values

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        super()._forward_value_estimator_keys(**kwargs)
        if getattr(self, "_cost_value_estimator", None) is not None:
            self._set_cost_estimator_keys()

    def _set_cost_estimator_keys(self) -> None:
        keys = self.tensor_keys
        self._cost_value_estimator.set_keys(
            advantage=keys.cost_advantage,
            value_target=keys.cost_value_target,
            value=keys.cost_value,
            reward=keys.cost,
            done=keys.done,
            terminated=keys.terminated,
        )

    def make_value_estimator(self, value_type: ValueEstimators = None, **hyperparams):
        """Build torchrl's GAE for the reward (as ``ClipPPOLoss``) and a second GAE, with the
        same ``gamma`` and ``lmbda``, on the cost with the cost value network."""
        super().make_value_estimator(value_type, **hyperparams)
        reward_gae = self._value_estimator
        if not isinstance(reward_gae, GAE):
            raise NotImplementedError(
                f"PPOLagLoss supports GAE value estimators only, got {type(reward_gae).__name__}."
            )
        self._cost_value_estimator = GAE(
            gamma=reward_gae.gamma.clone(),
            lmbda=reward_gae.lmbda.clone(),
            value_network=self.cost_critic_network,
            average_gae=reward_gae.average_gae,
            differentiable=False,
            vectorized=reward_gae._vectorized,
            shifted=reward_gae.shifted,
            time_dim=reward_gae.time_dim,
        )
        self._set_cost_estimator_keys()
        return self

    @property
    def cost_value_estimator(self) -> GAE:
        """The cost GAE (built with the reward one by :meth:`make_value_estimator`)."""
        if self._cost_value_estimator is None:
            self.make_value_estimator()
        return self._cost_value_estimator

    @property
    @_cache_values
    def _cached_cost_critic_network_params_detached(self):
        return self.cost_critic_network_params.detach()

    def compute_advantages(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write the reward and cost advantages and value targets into ``tensordict`` (in place).

        Call it on the whole collected batch ``[*B, T]`` (time last) before the PPO epochs.
        """
        self.value_estimator(
            tensordict,
            params=self._cached_critic_network_params_detached,
            target_params=self.target_critic_network_params,
        )
        self._cost_advantage(tensordict)
        return tensordict

    def _cost_advantage(self, tensordict: TensorDictBase) -> None:
        key = _next(self.tensor_keys.cost)
        cost = tensordict.get(key)
        if cost.shape == tensordict.batch_size:
            tensordict.set(key, cost.unsqueeze(-1))
        elif cost.shape != (*tensordict.batch_size, 1):
            raise ValueError(
                f"PPOLagLoss handles one cost: {key} must have shape {tuple(tensordict.batch_size)}"
                f" or {(*tensordict.batch_size, 1)}, got {tuple(cost.shape)}."
            )
        self.cost_value_estimator(
            tensordict, params=self._cached_cost_critic_network_params_detached
        )

    # ------------------------------------------------------------------ losses
    def _maybe_normalize_advantage(
        self, advantage: Tensor, tensordict: TensorDictBase, *, update_norm: bool
    ) -> Tensor:
        # ClipPPOLoss.forward calls this once, between the advantage and the ratio: the place
        # where the cost advantage enters.
        advantage = super()._maybe_normalize_advantage(
            advantage, tensordict, update_norm=update_norm
        )
        cost_advantage = tensordict.get(self.tensor_keys.cost_advantage)
        if self.normalize_advantage and cost_advantage.numel() > 1:
            cost_advantage = self._standardize_advantage(cost_advantage, tensordict)
        lagrangian = self.lagrangian
        if self.cost_surrogate == "clipped":
            advantage = advantage - lagrangian * cost_advantage
            if self.rescaling:
                advantage = advantage / (1.0 + lagrangian.sum())
        else:
            self._last_cost_advantage = cost_advantage
        return advantage

    def _log_weight(self, tensordict: TensorDictBase, adv_shape: torch.Size):
        out = super()._log_weight(tensordict, adv_shape)
        log_weight, _, _, log_is_weight = out
        # The surrogate's ratio pi_theta / pi_behav, as ClipPPOLoss weights its first gain.
        self._last_log_ratio = log_weight if log_is_weight is None else log_weight + log_is_weight
        return out

    def loss_cost_critic(self, tensordict: TensorDictBase) -> Tensor:
        """``critic_coeff * distance(V_c(s), R_c)``, unreduced (``[*B, 1]``)."""
        if self.separate_losses:
            tensordict = tensordict.detach()
        target = tensordict.get(self.tensor_keys.cost_value_target)
        td = tensordict.select(*self.cost_critic_network.in_keys, strict=False).copy()
        with self.cost_critic_network_params.to_module(
            self.cost_critic_network, preserve_module_state=False
        ):
            value = self.cost_critic_network(td).get(self.tensor_keys.cost_value)
        loss = distance_loss(target, value, loss_function=self.loss_critic_type)
        if self.clip_value:
            old_value = tensordict.get(self.tensor_keys.cost_value)
            loss, _ = _clip_value_loss(
                old_value, value, self.clip_value, target, loss, self.loss_critic_type
            )
        return self.critic_coeff * loss

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = tensordict.clone(False)
        if tensordict.get(self.tensor_keys.cost_advantage, None) is None:
            self._cost_advantage(tensordict)
        try:
            td_out = super().forward(tensordict)
            if self.cost_surrogate == "unclipped":
                log_ratio = self._last_log_ratio
                cost_advantage = _broadcast_advantage_to_log_weight(
                    self._last_cost_advantage, log_ratio
                )
                cost_term = log_ratio.exp() * (self.lagrangian * cost_advantage)
                cost_term = self._reduce_loss(cost_term, tensordict).squeeze(-1)
                loss_objective = td_out.get("loss_objective") + cost_term
                if self.rescaling:
                    loss_objective = loss_objective / (1.0 + self.lagrangian.sum())
                td_out.set("loss_objective", loss_objective)
        finally:
            self._last_log_ratio = None
            self._last_cost_advantage = None
        loss_cost_critic = self._reduce_loss(self.loss_cost_critic(tensordict), tensordict)
        td_out.set("loss_cost_critic", loss_cost_critic.squeeze(-1))
        td_out.set("lagrangian", self.lagrangian.detach().clone())
        self._clear_weakrefs(
            tensordict,
            td_out,
            "actor_network_params",
            "critic_network_params",
            "cost_critic_network_params",
            "target_actor_network_params",
            "target_critic_network_params",
        )
        return td_out
