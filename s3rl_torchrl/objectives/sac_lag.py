"""SAC-Lagrangian loss (FSRL's SACLagrangian, the base of S3RL) as a torchrl ``SACLoss`` subclass.

For ``m >= 1`` costs read from ``("next", "cost")`` (trailing dimension ``m``), with one double
reward critic ``Q_0j`` and one double cost critic ``Q_ij`` per cost ``i``:

    y_0 = r^(n) + gamma^k (1 - terminated) [min_j Q'_0j(s', a') - alpha log pi(a'|s')]
    y_i = c_i^(n) + gamma^k (1 - terminated) [min_j Q'_ij(s', a') - alpha log pi(a'|s')]
    L_pi = mean(alpha log pi(a|s) - min_j Q_0j(s, a)) + sum_i lambda_i mean(min_j Q_ij(s, a))
    L_pi = L_pi / (1 + sum_i lambda_i)                                  (rescaling)

with ``r^(n)``, ``c^(n)``, ``s'`` and ``k = steps_to_next_obs`` from
:func:`~s3rl_torchrl.objectives.make_nstep_transform` (1-step data works too: ``k`` defaults to
1). The entropy term in ``y_i`` is the ``entropy_in_cost_target`` switch (FSRL and the paper: on).
``a'`` is one sample shared by all targets and ``a`` one reparameterised sample shared by the
reward and cost terms of the actor loss.

The formulas above are FSRL's (the defaults). Three switches make the cost critic sound under a
large multiplier (docs/objectives.md, "Sound critics"); each replaces one piece:

- ``cost_critic_read``: how the cost pair is read in ``y_i`` and ``L_pi``: ``"min"`` (FSRL; an
  optimistic read for a cost the actor minimises), ``"max"`` (pessimistic, as CAL's upper
  confidence bound of its cost ensemble) or ``"mean"``;
- ``cost_nonnegative``: the cost critic's bootstrap value and its read in ``L_pi`` are clamped at
  0 (every cost is >= 0, so is every cost value);
- ``cost_gamma``: the cost critics' own discount (``gamma`` by default): a shorter horizon ranks
  the actions by the costs they bring soon, where a cost that lasts for most of an episode
  flattens ``Q_c`` across actions;
- ``entropy_rescaling=False``: only the reward and cost terms are divided by ``1 + sum lambda``,
  ``L_pi = mean(alpha log pi) + mean(sum_i lambda_i Q_i - Q_0) / (1 + sum_i lambda_i)``, so that
  automatic alpha does not have to grow with lambda to hold its target entropy.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import torch
from tensordict import TensorDict, TensorDictBase, TensorDictParams
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, dispatch
from tensordict.utils import NestedKey
from torch import Tensor
from torchrl.data.tensor_specs import TensorSpec
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives.sac import SACLoss, compute_rsample_log_prob
from torchrl.objectives.utils import (
    ValueEstimators,
    _cache_values,
    _vmap_func,
    distance_loss,
)

from s3rl_torchrl.modules.batched_mlp import BatchedMLP
from s3rl_torchrl.objectives._lagrangian_buffer import LagrangianBufferMixin

__all__ = ["SACLagLoss", "SACLagOptimizers", "make_sac_lag_optimizers", "sac_lag_update"]

_LOSS_FUNCTIONS = ("l2", "l1", "smooth_l1")
_CRITIC_EVAL_CHOICES = ("auto", "batched_mlp", "fused_vmap", "vmap")
#: How a cost critic pair (or ensemble) is read into one value: FSRL's optimistic ``min``, the
#: pessimistic ``max`` (CAL's reading of a cost ensemble through an upper bound), or the ``mean``.
COST_CRITIC_READS = ("min", "max", "mean")


def _detached(params: TensorDictBase) -> TensorDictBase:
    """``params.detach()`` (SACLoss's) without locking the copy: ``detach()`` of locked
    ``TensorDictParams`` locks its result, and tensordict warns about a ``lock_()`` inside a
    compiled graph at every compile of the loss."""
    return params.apply(Tensor.detach, filter_empty=True)


def _next(key: NestedKey) -> tuple[str, ...]:
    return ("next", *key) if isinstance(key, tuple) else ("next", key)


def _is_module_list(module) -> bool:
    return isinstance(module, (list, tuple))


class SACLagLoss(LagrangianBufferMixin, SACLoss):
    r"""SAC with Lagrangian cost penalties (FSRL's SAC-Lag), TensorDict-native.

    A subclass of :class:`torchrl.objectives.SACLoss` (version 2, no value network) that adds one
    double cost critic per cost, n-step reward and cost targets masked on ``terminated`` only, and
    the Lagrangian actor loss (module docstring). ``lagrangian`` is a buffer of shape ``[m]``
    set from outside, typically by a :class:`~s3rl_torchrl.objectives.PIDLagrangian` once per
    collect: ``loss.lagrangian = controller.update(mean_episode_cost)``.

    With ``lagrangian = 0`` the actor, reward-critic and alpha losses equal ``SACLoss``'s on the
    same networks, batch and random state; with ``cost_qvalue_network=None`` (no cost critics)
    the whole loss is ``SACLoss``.

    Args:
        actor_network: stochastic actor (e.g. ``ProbabilisticActor`` with ``TanhNormal``).
        qvalue_network: reward critic ``[observation, action] -> "state_action_value"``
            (``[..., 1]``); one module (copied ``num_qvalue_nets`` times, copies resampled by
            torchrl) or a list of ``num_qvalue_nets`` modules (each keeps its own init).
        cost_qvalue_network: cost critic ``[observation, action] -> "state_action_cost_value"``
            (``[..., 1]``, one cost per network); one module (copied ``num_qvalue_nets *
            num_costs`` times) or a list of that many modules ordered ``[cost 0 net 0, cost 0
            net 1, cost 1 net 0, ...]``. ``None`` gives unconstrained SAC.

    Keyword Args:
        num_costs: number of cost signals ``m`` (trailing dimension of ``("next", "cost")``).
            Defaults to 1 with a cost critic and 0 without.
        num_qvalue_nets: critics per signal (2: double Q as in FSRL).
        loss_function: critic regression loss, one of ``"l2"`` (FSRL: squared error, summed
            over the critics), ``"l1"``, ``"smooth_l1"`` (``SACLoss``'s default).
        alpha_init: initial entropy coefficient, also when it is auto-tuned (paper: 0.005).
        min_alpha, max_alpha, action_spec, fixed_alpha, target_entropy: as in ``SACLoss``
            (``target_entropy="auto"`` is ``-action_dim``).
        delay_qvalue: keep target critics (updated by ``SoftUpdate``); both reward and cost.
        entropy_in_cost_target: subtract ``alpha log pi(a'|s')`` in the cost targets (FSRL and
            the paper: ``True``; OmniSafe: ``False``).
        rescaling: divide the whole actor loss by ``1 + sum(lagrangian)`` (FSRL/paper: ``True``).
        entropy_rescaling: with ``rescaling``, divide the entropy term too (FSRL: ``True``);
            ``False`` divides only the reward and cost terms, so alpha does not grow with lambda.
        cost_critic_read: ``"min"`` (FSRL), ``"max"`` or ``"mean"`` of the cost critics, in the
            cost targets and in the actor loss (module docstring).
        cost_nonnegative: clamp the cost critics' bootstrap value and their read in the actor
            loss at 0 (FSRL: ``False``).
        cost_gamma: the cost critics' discount; ``None`` (FSRL): the value estimator's gamma.
            n-step cost sums must use it too (``make_nstep_transform(cost_gamma=...)``).
        lagrangian_init: initial ``lagrangian`` (float or ``m`` values, >= 0).
        critic_eval: how the critics are evaluated (same numbers up to float rounding, speed
            differs, see ``docs/objectives.md``): ``"batched_mlp"`` runs every reward and cost
            critic in one chain of batched matmuls (needs critics that are torchrl ``MLP``\ s of
            ``Linear`` + elementwise activations with one architecture, e.g. from
            ``build_qvalue_network``); ``"fused_vmap"`` runs them in one vmapped call (same
            architecture, any module); ``"vmap"`` runs reward and cost critics in two vmapped
            calls (any modules). ``"auto"`` (default) picks the first that applies.
        separate_losses, reduction, deactivate_vmap, use_prioritized_weights,
            scalar_output_mode: as in ``SACLoss``.

    Keys (``loss.set_keys(...)``): those of ``SACLoss`` plus ``cost`` (read at
    ``("next", cost)``, default ``"cost"``), ``state_action_cost_value`` (the cost critic's
    output) and ``steps_to_next_obs`` (root entry, default ``"steps_to_next_obs"``).

    The forward returns ``loss_actor``, ``loss_qvalue`` (reward critics), ``loss_cost_qvalue``
    (cost critics) and ``loss_alpha``, whose sum is what to minimise, and the diagnostics
    ``reward_q`` (mean over the batch of ``min_j Q_0j(s, a~pi)``), ``cost_q`` (``[m]``, the same
    for each cost), ``lagrangian`` (``[m]``), ``entropy`` and ``alpha``.

    The discount is set, as for every torchrl loss, with ``loss.make_value_estimator(gamma=...)``
    (only TD(0) is supported: n-step returns come from the replay buffer transform).
    """

    @dataclass
    class _AcceptedKeys(SACLoss._AcceptedKeys):
        """Tensordict keys of :class:`SACLagLoss`: ``SACLoss``'s plus the cost ones.

        Attributes:
            cost: cost entry, read at ``("next", cost)``, trailing dimension ``num_costs``.
            state_action_cost_value: output key of the cost critic.
            steps_to_next_obs: root entry with the number of steps between the observation
                and the bootstrap observation (written by the n-step transform).
        """

        cost: NestedKey = "cost"
        state_action_cost_value: NestedKey = "state_action_cost_value"
        steps_to_next_obs: NestedKey = "steps_to_next_obs"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    SUPPORTED_VALUE_ESTIMATORS = (ValueEstimators.TD0,)
    _schedulable_buffers = frozenset(SACLoss._schedulable_buffers | {"lagrangian"})

    cost_qvalue_network: TensorDictModule
    cost_qvalue_network_params: TensorDictParams
    target_cost_qvalue_network_params: TensorDictParams

    def __init__(
        self,
        actor_network: ProbabilisticTensorDictSequential,
        qvalue_network: TensorDictModule | list[TensorDictModule],
        cost_qvalue_network: TensorDictModule | list[TensorDictModule] | None = None,
        *,
        num_costs: int | None = None,
        num_qvalue_nets: int = 2,
        loss_function: str = "l2",
        alpha_init: float = 0.005,
        min_alpha: float | None = None,
        max_alpha: float | None = None,
        action_spec: TensorSpec | None = None,
        fixed_alpha: bool = False,
        target_entropy: str | float = "auto",
        delay_qvalue: bool = True,
        entropy_in_cost_target: bool = True,
        rescaling: bool = True,
        entropy_rescaling: bool = True,
        cost_critic_read: Literal["min", "max", "mean"] = "min",
        cost_nonnegative: bool = False,
        cost_gamma: float | None = None,
        lagrangian_init: float | Sequence[float] | Tensor = 0.0,
        critic_eval: Literal["auto", "batched_mlp", "fused_vmap", "vmap"] = "auto",
        separate_losses: bool = False,
        reduction: str | None = None,
        deactivate_vmap: bool = False,
        use_prioritized_weights: str | bool = "auto",
        scalar_output_mode: str | None = None,
    ) -> None:
        if num_costs is None:
            num_costs = 0 if cost_qvalue_network is None else 1
        if isinstance(num_costs, bool) or not isinstance(num_costs, int) or num_costs < 0:
            raise ValueError(f"num_costs must be an integer >= 0, got {num_costs!r}.")
        if cost_qvalue_network is None and num_costs > 0:
            raise ValueError(
                f"num_costs={num_costs} needs a cost_qvalue_network; pass one, or num_costs=0 "
                "(unconstrained SAC)."
            )
        if cost_qvalue_network is not None and num_costs == 0:
            raise ValueError(
                "num_costs=0 means no cost critic, but a cost_qvalue_network was given."
            )
        if isinstance(num_qvalue_nets, bool) or not isinstance(num_qvalue_nets, int):
            raise ValueError(f"num_qvalue_nets must be an integer >= 1, got {num_qvalue_nets!r}.")
        if num_qvalue_nets < 1:
            raise ValueError(f"num_qvalue_nets must be an integer >= 1, got {num_qvalue_nets!r}.")
        if loss_function not in _LOSS_FUNCTIONS:
            raise ValueError(
                f"Unknown loss_function {loss_function!r}; valid choices are "
                f"{', '.join(_LOSS_FUNCTIONS)}."
            )
        if cost_critic_read not in COST_CRITIC_READS:
            raise ValueError(
                f"Unknown cost_critic_read {cost_critic_read!r}; valid choices are "
                f"{', '.join(map(repr, COST_CRITIC_READS))}."
            )
        if cost_gamma is not None and not 0.0 <= cost_gamma <= 1.0:
            raise ValueError(f"cost_gamma must be in [0, 1] or None, got {cost_gamma!r}.")
        if critic_eval not in _CRITIC_EVAL_CHOICES:
            raise ValueError(
                f"Unknown critic_eval {critic_eval!r}; valid choices are "
                f"{', '.join(map(repr, _CRITIC_EVAL_CHOICES))}."
            )
        if not (alpha_init > 0 and math.isfinite(alpha_init)):
            raise ValueError(f"alpha_init must be a positive finite number, got {alpha_init!r}.")
        if reduction is not None and reduction not in ("mean", "sum", "none"):
            raise ValueError(
                f"Unknown reduction {reduction!r}; valid choices are 'mean', 'sum', 'none'."
            )
        if _is_module_list(cost_qvalue_network) and len(cost_qvalue_network) != (
            num_qvalue_nets * num_costs
        ):
            raise ValueError(
                f"cost_qvalue_network is a list of {len(cost_qvalue_network)} modules; with "
                f"num_costs={num_costs} and num_qvalue_nets={num_qvalue_nets} it must hold "
                f"{num_qvalue_nets * num_costs} (one per cost and critic), or pass one module."
            )
        if _is_module_list(qvalue_network) and len(qvalue_network) != num_qvalue_nets:
            raise ValueError(
                f"qvalue_network is a list of {len(qvalue_network)} modules; it must hold "
                f"num_qvalue_nets={num_qvalue_nets}, or pass one module."
            )
        super().__init__(
            actor_network,
            qvalue_network,
            None,
            num_qvalue_nets=num_qvalue_nets,
            loss_function=loss_function,
            alpha_init=alpha_init,
            min_alpha=min_alpha,
            max_alpha=max_alpha,
            action_spec=action_spec,
            fixed_alpha=fixed_alpha,
            target_entropy=target_entropy,
            delay_actor=False,
            delay_qvalue=delay_qvalue,
            separate_losses=separate_losses,
            reduction=reduction,
            deactivate_vmap=deactivate_vmap,
            use_prioritized_weights=use_prioritized_weights,
            scalar_output_mode=scalar_output_mode,
        )
        self.num_costs = num_costs
        self.entropy_in_cost_target = bool(entropy_in_cost_target)
        self.rescaling = bool(rescaling)
        self.entropy_rescaling = bool(entropy_rescaling)
        self.cost_critic_read = cost_critic_read
        self.cost_nonnegative = bool(cost_nonnegative)
        self.cost_gamma = None if cost_gamma is None else float(cost_gamma)
        self._init_lagrangian(lagrangian_init, device=self.log_alpha.device)

        if num_costs > 0:
            policy_params = list(actor_network.parameters()) if separate_losses else None
            self.convert_to_functional(
                cost_qvalue_network,
                "cost_qvalue_network",
                num_qvalue_nets * num_costs,
                create_target_params=delay_qvalue,
                compare_against=policy_params,
            )
        else:
            self.cost_qvalue_network = None
        self._critic_eval = self._resolve_critic_eval(critic_eval)
        self._set_in_keys()  # SACLoss computed them before the cost entries existed
        self._make_cost_vmap()
        # SACLoss turns "auto" into a target-entropy buffer on first use, which may be the first
        # state_dict (a checkpoint) after a compiled forward: the module then changes under
        # dynamo's guards and the loss recompiles (~10 s). Settle it now when the spec allows.
        with contextlib.suppress(RuntimeError):
            _ = self.target_entropy  # the property registers the buffer

    # ------------------------------------------------------------------ configuration
    def _same_architecture(self) -> bool:
        reward, cost = self.qvalue_network, self.cost_qvalue_network
        if list(reward.in_keys) != list(cost.in_keys) or len(reward.out_keys) != 1:
            return False
        inner_r, inner_c = getattr(reward, "module", reward), getattr(cost, "module", cost)
        if type(inner_r) is not type(inner_c) or repr(inner_r) != repr(inner_c):
            return False
        params_r = self.qvalue_network_params.flatten_keys()
        params_c = self.cost_qvalue_network_params.flatten_keys()
        if set(params_r.keys()) != set(params_c.keys()):
            return False
        return all(
            params_r[k].shape[1:] == params_c[k].shape[1:]
            and params_r[k].dtype == params_c[k].dtype
            for k in params_r.keys()
        )

    def _resolve_critic_eval(self, choice: str) -> str:
        same = self.num_costs == 0 or self._same_architecture()
        batched = BatchedMLP.from_module(self.qvalue_network, self.qvalue_network_params)
        if batched is not None and self.num_costs:
            cost_batched = BatchedMLP.from_module(
                self.cost_qvalue_network, self.cost_qvalue_network_params
            )
            if cost_batched is None or not same:
                batched = None
        self._batched_mlp = batched
        available = {"batched_mlp": batched is not None, "fused_vmap": same, "vmap": True}
        if choice == "auto":
            return next(mode for mode, ok in available.items() if ok)
        if not available[choice]:
            need = (
                "critics that are torchrl MLPs (Linear + elementwise activations) with one "
                "architecture for reward and costs"
                if choice == "batched_mlp"
                else "reward and cost critics with the same architecture and input keys"
            )
            raise ValueError(f"critic_eval={choice!r} needs {need}; use 'auto' or 'vmap'.")
        return choice

    @property
    def critic_eval(self) -> str:
        """The critic evaluation in use: ``"batched_mlp"``, ``"fused_vmap"`` or ``"vmap"``."""
        return self._critic_eval

    def _make_cost_vmap(self) -> None:
        if getattr(self, "num_costs", 0) > 0:
            self._vmap_cost_qnetworkN0 = _vmap_func(
                self.cost_qvalue_network,
                (None, 0),
                randomness=self.vmap_randomness,
                pseudo_vmap=self.deactivate_vmap,
            )

    def _make_vmap(self):
        super()._make_vmap()
        # SACLoss.__init__ calls this before the cost critic exists.
        if "cost_qvalue_network" in self.__dict__:
            self._make_cost_vmap()

    # ------------------------------------------------------------------ keys
    def _forward_value_estimator_keys(self, **kwargs) -> None:
        super()._forward_value_estimator_keys(**kwargs)
        self._set_in_keys()

    def _set_in_keys(self):
        super()._set_in_keys()
        keys = set(self._in_keys)
        if getattr(self, "num_costs", 0) > 0:
            keys.add(_next(self.tensor_keys.cost))
            keys.update(self.cost_qvalue_network.in_keys)
        self._in_keys = list(keys)

    @property
    def out_keys(self):
        if self._out_keys is None:
            self._out_keys = [
                "loss_actor",
                "loss_qvalue",
                "loss_cost_qvalue",
                "loss_alpha",
                "alpha",
                "entropy",
                "reward_q",
                "cost_q",
                "lagrangian",
            ]
        return self._out_keys

    @out_keys.setter
    def out_keys(self, values):
        self._out_keys = values

    # ------------------------------------------------------------------ critic evaluation
    def _critics(
        self, td: TensorDictBase, reward_params: TensorDictBase, cost_params: TensorDictBase | None
    ) -> tuple[Tensor, Tensor | None]:
        """All critics on ``td``: reward ``[N, *B]`` and cost ``[m, N, *B]`` values."""
        n, m = self.num_qvalue_nets, self.num_costs
        mode = self._critic_eval
        if mode == "vmap" or m == 0:
            if mode == "batched_mlp":
                reward = self._batched_mlp(td, (reward_params,))
            else:
                value_key = self.tensor_keys.state_action_value
                reward = self._vmap_qnetworkN0(td, reward_params).get(value_key).squeeze(-1)
            if m == 0:
                return reward, None
            td_cost = td.select(*self.cost_qvalue_network.in_keys, strict=False)
            cost = self._vmap_cost_qnetworkN0(td_cost, cost_params)
            cost = cost.get(self.tensor_keys.state_action_cost_value).squeeze(-1)
            return reward, cost.unflatten(0, (m, n))
        if mode == "batched_mlp":
            values = self._batched_mlp(td, (reward_params, cost_params))
        else:
            params = torch.cat([reward_params, cost_params], 0)
            value_key = self.tensor_keys.state_action_value
            values = self._vmap_qnetworkN0(td, params).get(value_key).squeeze(-1)
        return values[:n], values[n:].unflatten(0, (m, n))

    def _split_keys(self) -> tuple | None:
        """Critic inputs other than the action (``None``: the split path does not apply)."""
        if self._critic_eval != "batched_mlp":
            return None
        action = self.tensor_keys.action
        if action not in self._batched_mlp.in_keys:
            return None
        return tuple(key for key in self._batched_mlp.in_keys if key != action)

    def _param_parts(self, detached: bool) -> tuple[TensorDictBase, ...]:
        """Reward (and cost) critic parameters, in the order of the critic dimension."""
        if detached:
            parts = (self._cached_detached_qvalue_params,)
            return parts + ((self._cached_detached_cost_qvalue_params,) if self.num_costs else ())
        parts = (self.qvalue_network_params,)
        return parts + ((self.cost_qvalue_network_params,) if self.num_costs else ())

    def _critics_split(
        self, td: TensorDictBase, params: tuple[TensorDictBase, ...], shared: Tensor | None
    ) -> tuple[Tensor, Tensor | None, Tensor]:
        """Batched-MLP critics with the first layer split into non-action and action terms.

        ``shared`` is the non-action term (bias included); it is computed when ``None``.
        Returns reward ``[N, *B]``, cost ``[m, N, *B]`` values and the shared term.
        """
        mlp = self._batched_mlp
        if shared is None:
            shared = mlp.first_layer_term(td, params, self._split_keys(), bias=True)
        action_term = mlp.first_layer_term(td, params, (self.tensor_keys.action,), bias=False)
        values = mlp.from_first_layer(action_term.add_(shared), params, td.batch_size)
        n, m = self.num_qvalue_nets, self.num_costs
        if not m:
            return values, None, shared
        return values[:n], values[n:].unflatten(0, (m, n)), shared

    def _critic_input(self, tensordict: TensorDictBase) -> TensorDictBase:
        keys = list(self.qvalue_network.in_keys)
        if self.num_costs and self._critic_eval == "vmap":
            keys += list(self.cost_qvalue_network.in_keys)
        return tensordict.select(*keys, strict=False)

    def _get_cost(self, tensordict: TensorDictBase) -> Tensor:
        key = _next(self.tensor_keys.cost)
        cost = tensordict.get(key, None)
        if cost is None:
            raise KeyError(
                f"SACLagLoss with num_costs={self.num_costs} needs the cost entry {key}; set it "
                "with loss.set_keys(cost=...)."
            )
        expected = (*tensordict.batch_size, self.num_costs)
        if tuple(cost.shape) != expected:
            raise ValueError(
                f"SACLagLoss was built with num_costs={self.num_costs}: {key} must have shape "
                f"{expected} (batch + one entry per cost), got {tuple(cost.shape)}."
            )
        return cost

    # ------------------------------------------------------------------ targets
    def compute_targets(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor]:
        """Critic targets: reward ``[*B]`` and costs ``[*B, m]`` (no gradient).

        ``y = R + gamma ** steps_to_next_obs * (1 - terminated) * V'(s')`` with ``R`` the
        (n-step) reward/cost, ``s' = ("next", "observation")`` and
        ``V'_i = min_j Q'_ij(s', a') - alpha log pi(a'|s')`` (costs: entropy term only with
        ``entropy_in_cost_target``); one action ``a' ~ pi(.|s')`` shared by all targets.
        """
        keys = self.tensor_keys
        batch_size = tensordict.batch_size
        reward = tensordict.get(_next(keys.reward))
        cost = self._get_cost(tensordict) if self.num_costs else None
        with torch.no_grad():
            with (
                set_exploration_type(ExplorationType.RANDOM),
                self.actor_network_params.to_module(
                    self.actor_network, preserve_module_state=False
                ),
            ):
                next_td = tensordict.get("next").copy()
                next_dist = self.actor_network.get_dist(next_td)
                next_action, next_log_prob = compute_rsample_log_prob(next_dist)
            next_td.set(keys.action, next_action)
            q_reward, q_cost = self._critics(
                self._critic_input(next_td),
                self.target_qvalue_network_params,
                self.target_cost_qvalue_network_params if self.num_costs else None,
            )
            entropy_term = self._alpha * next_log_prob
            # SACLoss takes the min after subtracting alpha*log_pi; keep its order.
            next_value = (q_reward - entropy_term).min(0)[0].unsqueeze(-1)
            rewards = reward.reshape(*batch_size, 1)
            if q_cost is not None:
                if self.entropy_in_cost_target:
                    q_cost = q_cost - entropy_term
                next_cost_value = self.read_cost(q_cost).movedim(0, -1)
                if self.cost_nonnegative:
                    next_cost_value = next_cost_value.clamp_min(0.0)
                if self.cost_gamma is not None:
                    target = self._td0(tensordict, rewards, next_value)
                    cost_target = self._cost_td0(tensordict, cost.to(rewards.dtype), next_cost_value)
                    return target[..., 0], cost_target
                next_value = torch.cat([next_value, next_cost_value], -1)
                rewards = torch.cat([rewards, cost.to(rewards.dtype)], -1)
            target = self._td0(tensordict, rewards, next_value)
        return target[..., 0], target[..., 1:]

    def _cost_td0(self, tensordict: TensorDictBase, cost: Tensor, next_value: Tensor) -> Tensor:
        """``y_i = C_i + cost_gamma ** k (1 - terminated) V'_i`` (``[*B, m]``), k the steps to
        the bootstrap observation, as torchrl's TD(0) does with its own gamma."""
        keys = self.tensor_keys
        terminated = tensordict.get(_next(keys.terminated), None)
        if terminated is None:
            terminated = tensordict.get(_next(keys.done))
        alive = (~terminated.reshape(*tensordict.batch_size, 1)).to(cost.dtype)
        steps = tensordict.get(keys.steps_to_next_obs, None)
        if steps is None:
            discount = self.cost_gamma
        else:
            discount = self.cost_gamma ** steps.reshape(*tensordict.batch_size, 1).to(cost.dtype)
        return cost + discount * alive * next_value

    def _td0(self, tensordict: TensorDictBase, rewards: Tensor, next_value: Tensor) -> Tensor:
        """torchrl's TD(0) estimate for several signals at once (one column per signal)."""
        keys = self.tensor_keys
        estimator = self.value_estimator
        est_keys = estimator.tensor_keys
        terminated = tensordict.get(_next(keys.terminated), None)
        done = tensordict.get(_next(keys.done), None)
        if terminated is None:
            terminated = done
        if terminated is None:
            raise KeyError(f"SACLagLoss needs {_next(keys.terminated)} in the batch.")
        shape = rewards.shape
        flags = terminated.reshape(*tensordict.batch_size, 1).expand(shape)
        # TD(0) reads only `terminated` when it is present; `done` is there for its key checks.
        entries = {
            _next(est_keys.reward): rewards,
            _next(est_keys.terminated): flags,
            _next(est_keys.done): flags,
        }
        steps = tensordict.get(keys.steps_to_next_obs, None)
        if steps is not None:
            entries[est_keys.steps_to_next_obs] = steps.reshape(*tensordict.batch_size, 1).expand(
                shape
            )
        td = TensorDict(entries, batch_size=tensordict.batch_size)
        return estimator.value_estimate(td, next_value=next_value)

    # ------------------------------------------------------------------ losses
    def qvalue_v2_loss(self, tensordict: TensorDictBase) -> tuple[Tensor, dict[str, Tensor]]:
        """Reward-critic loss; the cost-critic loss is in the metadata (``loss_cost_qvalue``)."""
        weights = self._maybe_get_priority_weight(tensordict)
        target_reward, target_cost = self.compute_targets(tensordict)
        shared = None
        if self._split_keys() is not None:
            pred_reward, pred_cost, shared = self._critics_split(
                tensordict, self._param_parts(detached=False), None
            )
        else:
            pred_reward, pred_cost = self._critics(
                self._critic_input(tensordict),
                self.qvalue_network_params,
                self.cost_qvalue_network_params if self.num_costs else None,
            )
        td_error = (pred_reward - target_reward).abs()
        loss_qvalue = distance_loss(
            pred_reward, target_reward.expand_as(pred_reward), loss_function=self.loss_function
        ).sum(0)
        loss_qvalue = self._reduce_loss(loss_qvalue, tensordict=tensordict, weights=weights)
        if pred_cost is not None:
            # [*B, m] -> [m, 1, *B] to broadcast against the [m, N, *B] predictions.
            target = target_cost.movedim(-1, 0).unsqueeze(1).expand_as(pred_cost)
            loss_cost = distance_loss(pred_cost, target, loss_function=self.loss_function)
            loss_cost = loss_cost.sum((0, 1))
            loss_cost = self._reduce_loss(loss_cost, tensordict=tensordict, weights=weights)
        else:
            loss_cost = torch.zeros_like(loss_qvalue)
        metadata = {
            "td_error": td_error.detach().max(0)[0],
            "loss_cost_qvalue": loss_cost,
            "first_layer_shared": shared,
        }
        return loss_qvalue, metadata

    def critic_loss(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Critic losses only (``loss_qvalue``, ``loss_cost_qvalue``), for FSRL's update order.

        Also writes the reward TD error at the priority key, as ``SACLoss`` does.
        """
        loss_qvalue, metadata = self.qvalue_v2_loss(tensordict)
        tensordict.set(self.tensor_keys.priority, metadata["td_error"])
        batch_size = tensordict.batch_size if self.reduction == "none" else []
        return TensorDict(
            {"loss_qvalue": loss_qvalue, "loss_cost_qvalue": metadata["loss_cost_qvalue"]},
            batch_size=batch_size,
        )

    @property
    @_cache_values
    def _cached_detached_qvalue_params(self):
        return _detached(self.qvalue_network_params)

    @property
    @_cache_values
    def _cached_detached_cost_qvalue_params(self):
        # Cached like the reward counterpart: detached tensors share storage, so it stays current.
        return _detached(self.cost_qvalue_network_params)

    def actor_loss(self, tensordict: TensorDictBase) -> tuple[Tensor, dict[str, Tensor]]:
        """Lagrangian actor loss; metadata: ``log_prob`` (detached), ``reward_q``, ``cost_q``."""
        return self._actor_loss(tensordict, None)

    def _actor_loss(
        self, tensordict: TensorDictBase, shared: Tensor | None
    ) -> tuple[Tensor, dict[str, Tensor]]:
        weights = self._maybe_get_priority_weight(tensordict)
        with (
            set_exploration_type(ExplorationType.RANDOM),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
        ):
            dist = self.actor_network.get_dist(tensordict)
            action, log_prob = compute_rsample_log_prob(dist)
        td_q = self._critic_input(tensordict)
        td_q.set(self.tensor_keys.action, action)
        # Detached critic parameters (and shared term): the actor loss must not move the critics.
        if self._split_keys() is not None:
            shared = None if shared is None else shared.detach()
            q_reward, q_cost, _ = self._critics_split(
                td_q, self._param_parts(detached=True), shared
            )
        else:
            q_reward, q_cost = self._critics(
                td_q,
                self._cached_detached_qvalue_params,
                self._cached_detached_cost_qvalue_params if self.num_costs else None,
            )
        min_q_reward = q_reward.min(0)[0]
        if log_prob.shape != min_q_reward.shape:
            raise RuntimeError(
                f"Actor log-prob and Q-value shapes differ: {log_prob.shape} and "
                f"{min_q_reward.shape}."
            )
        terms = self._actor_terms(log_prob, min_q_reward, q_cost)
        metadata = {"log_prob": log_prob.detach(), "reward_q": min_q_reward.detach().mean()}
        if q_cost is not None:
            metadata["cost_q"] = terms.pop("cost_q").detach().flatten(1).mean(1)
        else:
            metadata["cost_q"] = min_q_reward.new_zeros(0)
        loss_actor = self._reduce_loss(terms["total"], tensordict=tensordict, weights=weights)
        return loss_actor, metadata

    def _actor_terms(
        self, log_prob: Tensor, min_q_reward: Tensor, q_cost: Tensor | None, detail: bool = False
    ) -> dict[str, Tensor]:
        """The actor loss per sample (``total``) and the cost critics' read ``cost_q``
        (``[m, *B]``); with ``detail``, also the loss's three terms as they enter it:
        ``entropy`` (``alpha log pi``), ``reward`` (``-Q_0``) and ``cost`` (``sum_i lambda_i
        Q_i``), each divided by ``1 + sum lambda`` where the loss divides it."""
        entropy = self._alpha * log_prob
        loss_actor = entropy - min_q_reward
        out = {"entropy": entropy, "reward": -min_q_reward} if detail else {}
        if q_cost is None:
            out["total"] = loss_actor
            return out
        lagrangian = self.lagrangian
        read_q_cost = self.read_cost(q_cost)  # [m, *B]
        if self.cost_nonnegative:
            read_q_cost = read_q_cost.clamp_min(0.0)
        lag = lagrangian.reshape(-1, *([1] * (read_q_cost.ndim - 1)))
        penalty = (lag * read_q_cost).sum(0)
        out["cost_q"] = read_q_cost
        if not self.rescaling:
            out["total"] = loss_actor + penalty
        elif self.entropy_rescaling:  # FSRL: the whole loss, entropy included
            out["total"] = (loss_actor + penalty) / (1.0 + lagrangian.sum())
        else:
            out["total"] = entropy + (penalty - min_q_reward) / (1.0 + lagrangian.sum())
        if detail:
            out["cost"] = penalty
            if self.rescaling:
                scale = 1.0 + lagrangian.sum()
                out["reward"], out["cost"] = -min_q_reward / scale, penalty / scale
                if self.entropy_rescaling:
                    out["entropy"] = entropy / scale
        return out

    def read_cost(self, q_cost: Tensor) -> Tensor:
        """The cost critics ``[m, N, *B]`` read into one value per cost ``[m, *B]``
        (``cost_critic_read``)."""
        if self.cost_critic_read == "min":
            return q_cost.min(1)[0]
        if self.cost_critic_read == "max":
            return q_cost.max(1)[0]
        return q_cost.mean(1)

    def actor_loss_terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The actor loss's terms, batch means, with gradients (diagnostics: which term drives
        the policy): ``entropy``, ``reward`` and ``cost`` as :meth:`_actor_terms` defines
        them; their sum is ``actor_loss`` for the same random draw. Eager only."""
        with (
            set_exploration_type(ExplorationType.RANDOM),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
        ):
            dist = self.actor_network.get_dist(tensordict)
            action, log_prob = compute_rsample_log_prob(dist)
        td_q = self._critic_input(tensordict)
        td_q.set(self.tensor_keys.action, action)
        q_reward, q_cost = self._critics(
            td_q,
            self._cached_detached_qvalue_params,
            self._cached_detached_cost_qvalue_params if self.num_costs else None,
        )
        terms = self._actor_terms(log_prob, q_reward.min(0)[0], q_cost, detail=True)
        terms.pop("cost_q", None)
        terms.pop("total")
        return {name: term.mean() for name, term in terms.items()}

    @torch.no_grad()
    def critic_values(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor | None]:
        """The current (not target) critics at ``(observation, action)`` of ``tensordict``:
        reward ``[N, *B]`` and cost ``[m, N, *B]`` (``None`` without cost critics)."""
        return self._critics(
            self._critic_input(tensordict),
            self.qvalue_network_params,
            self.cost_qvalue_network_params if self.num_costs else None,
        )

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        loss_qvalue, value_metadata = self.qvalue_v2_loss(tensordict)
        # Same critic parameters in both losses here: reuse the critic loss's observation term.
        loss_actor, metadata_actor = self._actor_loss(
            tensordict, value_metadata["first_layer_shared"]
        )
        weights = self._maybe_get_priority_weight(tensordict)
        loss_alpha = self._reduce_loss(
            self._alpha_loss(log_prob=metadata_actor["log_prob"]),
            tensordict=tensordict,
            weights=weights,
        )
        tensordict.set(self.tensor_keys.priority, value_metadata["td_error"])
        out = {
            "loss_actor": loss_actor,
            "loss_qvalue": loss_qvalue,
            "loss_cost_qvalue": value_metadata["loss_cost_qvalue"],
            "loss_alpha": loss_alpha,
        }
        diagnostics = {
            "alpha": self._alpha,
            "entropy": -metadata_actor["log_prob"].mean(),
            "reward_q": metadata_actor["reward_q"],
            "cost_q": metadata_actor["cost_q"],
            "lagrangian": self.lagrangian.detach().clone(),
        }
        if self.reduction == "none":
            td_out = TensorDict(out, batch_size=tensordict.batch_size)
            if self.scalar_output_mode == "non_tensor":
                for key, value in diagnostics.items():
                    td_out.set_non_tensor(key, value)
        else:
            td_out = TensorDict({**out, **diagnostics}, batch_size=[])
        self._clear_weakrefs(
            tensordict,
            td_out,
            "actor_network_params",
            "qvalue_network_params",
            "cost_qvalue_network_params",
            "target_actor_network_params",
            "target_qvalue_network_params",
            "target_cost_qvalue_network_params",
        )
        return td_out


class SACLagOptimizers(NamedTuple):
    """FSRL's three Adam optimisers: actor, critics (reward and cost together), alpha."""

    actor: torch.optim.Optimizer
    critic: torch.optim.Optimizer
    alpha: torch.optim.Optimizer | None


def make_sac_lag_optimizers(
    loss: SACLoss,
    actor_lr: float = 5e-4,
    critic_lr: float = 1e-3,
    alpha_lr: float = 3e-4,
    **adam_kwargs,
) -> SACLagOptimizers:
    """Adam optimisers over the loss's parameter groups (defaults: the paper's learning rates).

    Works for ``SACLagLoss`` and torchrl's ``SACLoss``. ``alpha`` is ``None`` with a fixed alpha.
    ``adam_kwargs`` go to every ``torch.optim.Adam``; without ``fused``/``foreach`` the fused
    implementation is used (measured ~4x faster than the default per-tensor loop on CPU).
    """
    if "fused" not in adam_kwargs and "foreach" not in adam_kwargs:
        adam_kwargs["fused"] = True
    for name, lr in (("actor_lr", actor_lr), ("critic_lr", critic_lr), ("alpha_lr", alpha_lr)):
        if not lr > 0:
            raise ValueError(f"{name} must be > 0, got {lr!r}.")
    actor_params = list(loss.actor_network_params.values(True, True))
    critic_params = list(loss.qvalue_network_params.values(True, True))
    if getattr(loss, "num_costs", 0):
        critic_params += list(loss.cost_qvalue_network_params.values(True, True))
    alpha = None
    if isinstance(loss.log_alpha, torch.nn.Parameter):
        alpha = torch.optim.Adam([loss.log_alpha], lr=alpha_lr, **adam_kwargs)
    return SACLagOptimizers(
        actor=torch.optim.Adam(actor_params, lr=actor_lr, **adam_kwargs),
        critic=torch.optim.Adam(critic_params, lr=critic_lr, **adam_kwargs),
        alpha=alpha,
    )


def sac_lag_update(
    loss: SACLagLoss,
    batch: TensorDictBase,
    optimizers: SACLagOptimizers,
    target_updater=None,
    *,
    critic_loss=None,
    actor_loss=None,
) -> TensorDictBase:
    """One gradient step in FSRL's order: critics, then actor, then alpha, then target update.

    Unlike one backward through ``loss(batch)``, the actor loss sees the critics *after* their
    step, as in FSRL. ``critic_loss`` / ``actor_loss`` default to the loss's methods; pass
    compiled versions (``torch.compile(loss.critic_loss)``) to compile the two halves.
    Returns the detached losses and diagnostics (the keys of ``SACLagLoss.forward``).
    """
    if loss.reduction == "none":
        raise ValueError(
            "sac_lag_update needs scalar losses: build the loss with reduction='mean'."
        )
    critic_loss = loss.critic_loss if critic_loss is None else critic_loss
    actor_loss = loss.actor_loss if actor_loss is None else actor_loss
    critic = critic_loss(batch)
    optimizers.critic.zero_grad(set_to_none=True)
    (critic["loss_qvalue"] + critic["loss_cost_qvalue"]).backward()
    optimizers.critic.step()

    loss_actor, metadata = actor_loss(batch)
    optimizers.actor.zero_grad(set_to_none=True)
    loss_actor.backward()
    optimizers.actor.step()

    weights = loss._maybe_get_priority_weight(batch)
    loss_alpha = loss._reduce_loss(
        loss.alpha_loss(metadata["log_prob"]), tensordict=batch, weights=weights
    )
    if optimizers.alpha is not None:
        optimizers.alpha.zero_grad(set_to_none=True)
        loss_alpha.backward()
        optimizers.alpha.step()
    if target_updater is not None:
        target_updater.step()
    return TensorDict(
        {
            "loss_actor": loss_actor.detach(),
            "loss_qvalue": critic["loss_qvalue"].detach(),
            "loss_cost_qvalue": critic["loss_cost_qvalue"].detach(),
            "loss_alpha": loss_alpha.detach(),
            "alpha": loss._alpha,
            "entropy": -metadata["log_prob"].mean(),
            "reward_q": metadata["reward_q"],
            "cost_q": metadata["cost_q"],
            "lagrangian": loss.lagrangian.detach().clone(),
        },
        batch_size=[],
    )
