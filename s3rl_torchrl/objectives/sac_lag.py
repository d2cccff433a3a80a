"""SAC-Lagrangian loss (FSRL's SACLagrangian, the base of S3RL) as a torchrl ``SACLoss`` subclass.

For ``m >= 1`` costs read from ``("next", "cost")`` (trailing dimension ``m``), with one double
reward critic ``Q_0j`` and one double cost critic ``Q_ij`` per cost ``i``:

    y_0 = r^(n) + gamma^k (1 - terminated) [min_j Q'_0j(s', a') - alpha log pi(a'|s')]
    y_i = c_i^(n) + gamma^k (1 - terminated) [min_j Q'_ij(s', a') - alpha log pi(a'|s')]
    L_pi = mean(alpha log pi(a|s) - min_j Q_0j(s, a)) + sum_i lambda_i mean(min_j Q_ij(s, a))
    L_pi = L_pi / (1 + sum_i lambda_i)                                  (rescaling)

``r^(n)``, ``c^(n)``, ``s'`` and ``k = steps_to_next_obs`` come from the n-step transform
(``s3rl_torchrl.transforms.make_nstep_transform``; 1-step data works too, ``k = 1``); ``a'``
is one sample shared by all targets, ``a`` one reparameterised sample shared by the actor
loss's terms. These are FSRL's formulas, the defaults; ``cost_critic_read``,
``cost_nonnegative``, ``entropy_in_cost_target`` and ``entropy_rescaling`` make the cost critic
sound under a large multiplier (docs/objectives.md, "Sound critics").

As torchrl's ``TQCLoss`` does, it changes ``SACLoss`` through the critic loss
(:meth:`qvalue_v2_loss`, with the cost critics), the targets (:meth:`compute_targets`) and the
actor loss (:meth:`actor_loss`), evaluating the critics as ``SACLoss`` does (``vmap``). The
gradient steps that use it are in ``s3rl_torchrl/algorithms/sac.py``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict import TensorDict, TensorDictBase, TensorDictParams
from tensordict.nn import ProbabilisticTensorDictSequential, TensorDictModule, dispatch
from tensordict.utils import NestedKey
from torch import Tensor
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives.sac import SACLoss, compute_rsample_log_prob
from torchrl.objectives.utils import ValueEstimators, _cache_values, _vmap_func, distance_loss

from s3rl_torchrl.objectives._common import check_arguments, detached, parameter_containers
from s3rl_torchrl.objectives._common import next_key as _next
from s3rl_torchrl.objectives._lagrangian_buffer import LagrangianBufferMixin

__all__ = ["COST_CRITIC_READS", "SACLagLoss"]

_LOSS_FUNCTIONS = ("l2", "l1", "smooth_l1")
#: How a cost critic pair (or ensemble) is read into one value: FSRL's optimistic ``min``, the
#: pessimistic ``max`` (CAL's reading of a cost ensemble through an upper bound), or the ``mean``.
COST_CRITIC_READS = ("min", "max", "mean")
# What SACLoss.forward clears the weak references of, and the cost critics'.
_PARAMETER_CONTAINERS = parameter_containers("actor", "qvalue", "cost_qvalue")


class SACLagLoss(LagrangianBufferMixin, SACLoss):
    """SAC with Lagrangian cost penalties (FSRL's SAC-Lag), TensorDict-native.

    ``SACLoss`` (version 2) plus one double cost critic per cost, n-step targets masked on
    ``terminated`` only, and the Lagrangian actor loss (module docstring). ``lagrangian`` is a
    ``[m]`` buffer set from outside, e.g. ``loss.lagrangian = controller.update(J)``. With
    ``lagrangian = 0`` the actor, reward-critic and alpha losses are ``SACLoss``'s; without cost
    critics (``cost_qvalue_network=None``) the whole loss is.

    Args:
        actor_network, qvalue_network: as in ``SACLoss``; a list of ``num_qvalue_nets``
            critics keeps each one's own init (one module is copied and resampled by torchrl).
        cost_qvalue_network: ``[observation, action] -> "state_action_cost_value"``, one module
            or a list of ``num_qvalue_nets * num_costs`` ordered ``[cost 0 net 0, cost 0 net 1,
            cost 1 net 0, ...]``.
        num_costs: ``m`` (default: 1 with a cost critic, 0 without).
        loss_function: ``"l2"`` (FSRL: squared error, summed over critics), ``"l1"``,
            ``"smooth_l1"``. alpha_init: also when auto-tuned (paper: 0.005).
        entropy_in_cost_target, rescaling, entropy_rescaling: FSRL's (on), see the formulas.
        cost_critic_read: ``"min"`` (FSRL), ``"max"`` or ``"mean"`` of a cost pair, in the
            actor loss, and in the targets unless ``cost_target_read`` is given.
        cost_target_read: the read in the cost targets alone (default: ``cost_critic_read``'s);
            e.g. ``"mean"`` there with ``"max"`` in the actor loss keeps the actor's caution
            without bootstrapping the max's over-read into every target.
        cost_nonnegative: clamp both reads at 0 (FSRL: off).
        lagrangian_init: a number or ``m`` values, >= 0.
        sac_kwargs: ``SACLoss``'s other arguments (``fixed_alpha``, ``action_spec``, ...).

    The forward returns ``loss_actor``, ``loss_qvalue``, ``loss_cost_qvalue``, ``loss_alpha``
    (their sum is what to minimise), ``reward_q`` and ``cost_q`` (the critics read at ``a~pi``,
    batch means), ``lagrangian``, ``entropy``, ``alpha``. The discount comes from
    ``loss.make_value_estimator(gamma=...)`` (TD(0) only: the n-step returns are in the data).
    """

    @dataclass
    class _AcceptedKeys(SACLoss._AcceptedKeys):
        """``SACLoss``'s keys plus the cost ones."""

        cost: NestedKey = "cost"  # read at ("next", cost), trailing dimension num_costs
        state_action_cost_value: NestedKey = "state_action_cost_value"  # the cost critic's output
        # Root entry: steps between the observation and the bootstrap one (n-step transform).
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
        delay_qvalue: bool = True,
        separate_losses: bool = False,
        entropy_in_cost_target: bool = True,
        rescaling: bool = True,
        entropy_rescaling: bool = True,
        cost_critic_read: Literal["min", "max", "mean"] = "min",
        cost_target_read: Literal["min", "max", "mean"] | None = None,
        cost_nonnegative: bool = False,
        lagrangian_init: float | Sequence[float] | Tensor = 0.0,
        **sac_kwargs,
    ) -> None:
        if num_costs is None:
            num_costs = 0 if cost_qvalue_network is None else 1
        if (cost_qvalue_network is None) != (num_costs == 0):
            raise ValueError(
                f"num_costs={num_costs} needs a cost_qvalue_network, or pass num_costs=0."
                if num_costs
                else "num_costs=0 means no cost critic, but a cost_qvalue_network was given."
            )
        check_arguments(
            networks={
                "qvalue_network": (qvalue_network, num_qvalue_nets),
                "cost_qvalue_network": (cost_qvalue_network, num_qvalue_nets * num_costs),
            },
            counts={"num_costs": (num_costs, 0), "num_qvalue_nets": (num_qvalue_nets, 1)},
            choices={
                "loss_function": (loss_function, _LOSS_FUNCTIONS),
                "cost_critic_read": (cost_critic_read, COST_CRITIC_READS),
                "cost_target_read": (cost_target_read or cost_critic_read, COST_CRITIC_READS),
                "reduction": (sac_kwargs.get("reduction") or "mean", ("mean", "sum", "none")),
            },
            alpha_init=alpha_init,
        )
        super().__init__(
            actor_network, qvalue_network, None, num_qvalue_nets=num_qvalue_nets,
            loss_function=loss_function, alpha_init=alpha_init, delay_actor=False,
            delay_qvalue=delay_qvalue, separate_losses=separate_losses, **sac_kwargs,
        )
        self.num_costs = num_costs
        self.entropy_in_cost_target = bool(entropy_in_cost_target)
        self.rescaling = bool(rescaling)
        self.entropy_rescaling = bool(entropy_rescaling)
        self.cost_critic_read = cost_critic_read
        self.cost_target_read = cost_target_read or cost_critic_read
        self.cost_nonnegative = bool(cost_nonnegative)
        self._init_lagrangian(lagrangian_init, device=self.log_alpha.device)
        if num_costs > 0:
            self.convert_to_functional(
                cost_qvalue_network, "cost_qvalue_network", num_qvalue_nets * num_costs,
                create_target_params=delay_qvalue,
                compare_against=list(actor_network.parameters()) if separate_losses else None,
            )
            self._make_vmap()
        else:
            self.cost_qvalue_network = None
        self._set_in_keys()  # SACLoss computed them before the cost entries existed
        self.out_keys = ["loss_actor", "loss_qvalue", "loss_cost_qvalue", "loss_alpha"]
        self.out_keys += ["alpha", "entropy", "reward_q", "cost_q", "lagrangian"]
        # SACLoss turns "auto" into a target-entropy buffer on first use, which may be the first
        # state_dict (a checkpoint) after a compiled forward: the module then changes under
        # dynamo's guards and the loss recompiles (~10 s). Settle it now when the spec allows.
        with contextlib.suppress(RuntimeError):
            _ = self.target_entropy  # the property registers the buffer

    # ------------------------------------------------------------------ cost critics
    def _make_vmap(self):
        super()._make_vmap()
        # SACLoss.__init__ calls this before the cost critics exist, and __init__ once after.
        if getattr(self, "cost_qvalue_network", None) is not None:
            self._vmap_cost_qnetworkN0 = _vmap_func(
                self.cost_qvalue_network,
                (None, 0),
                randomness=self.vmap_randomness,
                pseudo_vmap=self.deactivate_vmap,
            )

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

    def _critic_input(self, tensordict: TensorDictBase) -> TensorDictBase:
        keys = list(self.qvalue_network.in_keys)
        if self.num_costs:
            keys += list(self.cost_qvalue_network.in_keys)
        return tensordict.select(*keys, strict=False)

    # The parameters of each evaluation of the critics: the reward critics', the cost critics'.
    _CRITIC_PARAMS = {
        "current": ("qvalue_network_params", "cost_qvalue_network_params"),
        "detached": ("_cached_detached_qvalue_params", "_cached_detached_cost_qvalue_params"),
        "target": ("target_qvalue_network_params", "target_cost_qvalue_network_params"),
    }

    def _critics(self, td: TensorDictBase, params: str) -> tuple[Tensor, Tensor | None]:
        """Every critic on ``td`` (:meth:`_critic_input`) with its ``params`` (a key of
        ``_CRITIC_PARAMS``): reward ``[N, *B]`` and cost ``[m, N, *B]`` (or ``None``) values."""
        reward_params, cost_params = self._CRITIC_PARAMS[params]
        reward = self._vmap_qnetworkN0(td, getattr(self, reward_params))
        reward = reward.get(self.tensor_keys.state_action_value).squeeze(-1)
        if not self.num_costs:
            return reward, None
        td_cost = td.select(*self.cost_qvalue_network.in_keys, strict=False)
        cost = self._vmap_cost_qnetworkN0(td_cost, getattr(self, cost_params))
        cost = cost.get(self.tensor_keys.state_action_cost_value).squeeze(-1)
        return reward, cost.unflatten(0, (self.num_costs, self.num_qvalue_nets))

    @property
    @_cache_values
    def _cached_detached_qvalue_params(self):
        return detached(self.qvalue_network_params)

    @property
    @_cache_values
    def _cached_detached_cost_qvalue_params(self):  # detached tensors share storage: current
        return detached(self.cost_qvalue_network_params)

    def read_cost(self, q_cost: Tensor, how: str | None = None) -> Tensor:
        """The cost critics ``[m, N, *B]`` read into one value per cost ``[m, *B]``: through
        ``how`` (``"min"``, ``"max"`` or ``"mean"``; default ``cost_critic_read``, the actor
        loss's read)."""
        how = how or self.cost_critic_read
        if how == "min":
            return q_cost.min(1)[0]
        if how == "max":
            return q_cost.max(1)[0]
        return q_cost.mean(1)

    @torch.no_grad()
    def critic_values(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor | None]:
        """The current critics at ``(observation, action)`` of ``tensordict`` (``_critics``)."""
        return self._critics(self._critic_input(tensordict), "current")

    # ------------------------------------------------------------------ targets
    def _get_cost(self, tensordict: TensorDictBase) -> Tensor:
        key, shape = _next(self.tensor_keys.cost), (*tensordict.batch_size, self.num_costs)
        cost = tensordict.get(key, None)
        if cost is None or tuple(cost.shape) != shape:
            got = "none" if cost is None else f"shape {tuple(cost.shape)}"
            raise (KeyError if cost is None else ValueError)(
                f"SACLagLoss with num_costs={self.num_costs} needs {key} of shape {shape} (batch "
                f"+ one entry per cost; loss.set_keys(cost=...) renames it), got {got}."
            )
        return cost

    def compute_targets(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor]:
        """Critic targets ``y_0`` (reward, ``[*B]``) and ``y_i`` (costs, ``[*B, m]``) of the
        module docstring, without gradient, from one action ``a' ~ pi(.|s')``."""
        keys = self.tensor_keys
        reward = tensordict.get(_next(keys.reward))
        cost = self._get_cost(tensordict) if self.num_costs else None
        with torch.no_grad():
            next_td = tensordict.get("next").copy()
            next_action, next_log_prob = self._sample_action(next_td)
            next_td.set(keys.action, next_action)
            q_reward, q_cost = self._critics(self._critic_input(next_td), "target")
            entropy_term = self._alpha * next_log_prob
            # SACLoss takes the min after subtracting alpha*log_pi; keep its order.
            next_value = (q_reward - entropy_term).min(0)[0].unsqueeze(-1)
            rewards = reward.reshape(*tensordict.batch_size, 1)
            if q_cost is not None:
                if self.entropy_in_cost_target:
                    q_cost = q_cost - entropy_term
                next_cost_value = self.read_cost(q_cost, self.cost_target_read).movedim(0, -1)
                if self.cost_nonnegative:
                    next_cost_value = next_cost_value.clamp_min(0.0)
                next_value = torch.cat([next_value, next_cost_value], -1)
                rewards = torch.cat([rewards, cost.to(rewards.dtype)], -1)
            target = self._td0(tensordict, rewards, next_value)
        return target[..., 0], target[..., 1:]

    def _td0(self, tensordict: TensorDictBase, rewards: Tensor, next_value: Tensor) -> Tensor:
        """torchrl's TD(0) estimate for several signals at once (one column per signal)."""
        keys = self.tensor_keys
        est_keys = self.value_estimator.tensor_keys
        terminated = tensordict.get(_next(keys.terminated), None)
        if terminated is None:
            terminated = tensordict.get(_next(keys.done), None)
        if terminated is None:
            raise KeyError(f"SACLagLoss needs {_next(keys.terminated)} in the batch.")
        shape, batch = rewards.shape, tensordict.batch_size
        flags = terminated.reshape(*batch, 1).expand(shape)
        # TD(0) reads only `terminated` when it is present; `done` is there for its key checks.
        entries = {_next(est_keys.reward): rewards}
        entries |= {_next(est_keys.terminated): flags, _next(est_keys.done): flags}
        steps = tensordict.get(keys.steps_to_next_obs, None)
        if steps is not None:
            entries[est_keys.steps_to_next_obs] = steps.reshape(*batch, 1).expand(shape)
        td = TensorDict(entries, batch_size=batch)
        return self.value_estimator.value_estimate(td, next_value=next_value)

    # ------------------------------------------------------------------ losses
    def qvalue_v2_loss(self, tensordict: TensorDictBase) -> tuple[Tensor, dict[str, Tensor]]:
        """Reward-critic loss; the cost-critic loss is in the metadata (``loss_cost_qvalue``)."""
        weights = self._maybe_get_priority_weight(tensordict)
        target_reward, target_cost = self.compute_targets(tensordict)
        pred_reward, pred_cost = self._critics(self._critic_input(tensordict), "current")
        td_error = (pred_reward - target_reward).abs()
        loss_qvalue = distance_loss(
            pred_reward, target_reward.expand_as(pred_reward), loss_function=self.loss_function
        ).sum(0)
        loss_qvalue = self._reduce_loss(loss_qvalue, tensordict=tensordict, weights=weights)
        if pred_cost is None:
            loss_cost = torch.zeros_like(loss_qvalue)
        else:  # the targets [*B, m] -> [m, 1, *B], against the [m, N, *B] predictions
            target = target_cost.movedim(-1, 0).unsqueeze(1).expand_as(pred_cost)
            error = distance_loss(pred_cost, target, loss_function=self.loss_function)
            loss_cost = self._reduce_loss(error.sum((0, 1)), tensordict=tensordict, weights=weights)
        return loss_qvalue, {"td_error": td_error.detach().max(0)[0], "loss_cost_qvalue": loss_cost}

    def _sample_action(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor]:
        """One reparameterised action of the actor at ``tensordict`` and its log-prob."""
        with (
            set_exploration_type(ExplorationType.RANDOM),
            self.actor_network_params.to_module(self.actor_network, preserve_module_state=False),
        ):
            return compute_rsample_log_prob(self.actor_network.get_dist(tensordict))

    def _policy_sample(self, tensordict: TensorDictBase) -> tuple[Tensor, Tensor, Tensor | None]:
        """An action's log-prob and every critic at it (detached: the actor loss moves none)."""
        action, log_prob = self._sample_action(tensordict)
        td_q = self._critic_input(tensordict)
        td_q.set(self.tensor_keys.action, action)
        q_reward, q_cost = self._critics(td_q, "detached")
        return log_prob, q_reward, q_cost

    def actor_loss(self, tensordict: TensorDictBase) -> tuple[Tensor, dict[str, Tensor]]:
        """Lagrangian actor loss; metadata: ``log_prob`` (detached), ``reward_q``, ``cost_q``."""
        weights = self._maybe_get_priority_weight(tensordict)
        log_prob, q_reward, q_cost = self._policy_sample(tensordict)
        min_q_reward = q_reward.min(0)[0]
        if log_prob.shape != min_q_reward.shape:
            shapes = f"{log_prob.shape} and {min_q_reward.shape}"
            raise RuntimeError(f"Actor log-prob and Q-value shapes differ: {shapes}.")
        terms = self._actor_terms(log_prob, min_q_reward, q_cost)
        metadata = {"log_prob": log_prob.detach(), "reward_q": min_q_reward.detach().mean()}
        cost_q = terms.pop("cost_q", None)  # [m, *B]; none without cost critics
        no_cost = min_q_reward.new_zeros(0)
        metadata["cost_q"] = no_cost if cost_q is None else cost_q.detach().flatten(1).mean(1)
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
        if q_cost is None:
            terms = {"entropy": entropy, "reward": -min_q_reward} if detail else {}
            return {"total": entropy - min_q_reward, **terms}
        lagrangian = self.lagrangian
        cost_q = self.read_cost(q_cost)  # [m, *B]
        if self.cost_nonnegative:
            cost_q = cost_q.clamp_min(0.0)
        cost = (lagrangian.reshape(-1, *([1] * (cost_q.ndim - 1))) * cost_q).sum(0)
        scale = 1.0 + lagrangian.sum() if self.rescaling else None
        if scale is None:
            total = entropy - min_q_reward + cost
        elif self.entropy_rescaling:  # FSRL: the whole loss, entropy included
            total = (entropy - min_q_reward + cost) / scale
        else:
            total = entropy + (cost - min_q_reward) / scale
        out = {"total": total, "cost_q": cost_q}
        if detail:
            out |= {"entropy": entropy, "reward": -min_q_reward, "cost": cost}
            if scale is not None:
                out |= {"reward": -min_q_reward / scale, "cost": cost / scale}
                if self.entropy_rescaling:
                    out["entropy"] = entropy / scale
        return out

    def actor_loss_terms(self, tensordict: TensorDictBase) -> dict[str, Tensor]:
        """The actor loss's terms, batch means, with gradients (diagnostics: which term drives
        the policy): ``entropy``, ``reward`` and ``cost`` as :meth:`_actor_terms` defines
        them; their sum is ``actor_loss`` for the same random draw. Eager only."""
        log_prob, q_reward, q_cost = self._policy_sample(tensordict)
        terms = self._actor_terms(log_prob, q_reward.min(0)[0], q_cost, detail=True)
        terms.pop("cost_q", None)
        terms.pop("total")
        return {name: term.mean() for name, term in terms.items()}

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        # SACLoss.forward, with the entries it cannot give: it drops the metadata of its two
        # halves, where the cost critics' loss and the critics' reads are.
        loss_qvalue, value_metadata = self.qvalue_v2_loss(tensordict)
        loss_actor, metadata_actor = self.actor_loss(tensordict)
        weights = self._maybe_get_priority_weight(tensordict)
        loss_alpha = self._alpha_loss(log_prob=metadata_actor["log_prob"])
        loss_alpha = self._reduce_loss(loss_alpha, tensordict=tensordict, weights=weights)
        tensordict.set(self.tensor_keys.priority, value_metadata["td_error"])
        out = {"loss_actor": loss_actor, "loss_qvalue": loss_qvalue}
        out |= {"loss_cost_qvalue": value_metadata["loss_cost_qvalue"], "loss_alpha": loss_alpha}
        diagnostics = {"alpha": self._alpha, "entropy": -metadata_actor["log_prob"].mean()}
        diagnostics |= {key: metadata_actor[key] for key in ("reward_q", "cost_q")}
        diagnostics["lagrangian"] = self.lagrangian.detach().clone()
        if self.reduction == "none":
            td_out = TensorDict(out, batch_size=tensordict.batch_size)
            if self.scalar_output_mode == "non_tensor":
                for key, value in diagnostics.items():
                    td_out.set_non_tensor(key, value)
        else:
            td_out = TensorDict({**out, **diagnostics}, batch_size=[])
        self._clear_weakrefs(tensordict, td_out, *_PARAMETER_CONTAINERS)
        return td_out
