"""DDPG-Lagrangian loss (FSRL's ``DDPGLagrangian``) as a torchrl ``DDPGLoss`` subclass.

For ``m >= 1`` costs read from ``("next", "cost")`` (trailing dimension ``m``), a reward critic
``Q_r`` (``DDPGLoss``'s value network) and a cost critic ``Q_c`` with ``m`` outputs, a
deterministic actor ``mu`` and target copies ``mu'``, ``Q_r'``, ``Q_c'``:

    y_r = r^(n) + gamma^k (1 - terminated) Q_r'(s', mu'(s'))
    y_c = c^(n) + gamma^k (1 - terminated) Q_c'(s', mu'(s'))
    L_Q = mean((Q_r(s, a) - y_r)^2)      L_Qc = mean(sum_i (Q_ci(s, a) - y_ci)^2)
    L_mu = mean(-Q_r(s, mu(s)) + sum_i lambda_i Q_ci(s, mu(s)))
    L_mu = L_mu / (1 + sum_i lambda_i)                                   (rescaling)

as in FSRL's ``fsrl/policy/ddpg_lag.py`` (``critics_loss``, ``policy_loss``, with the
``safety_loss`` and rescaling of ``fsrl/policy/lagrangian_base.py``): one critic per signal (no
double Q), a target actor and target critics (``tau = 0.05``), n-step targets (``n_step = 2``;
here from :func:`~s3rl_torchrl.transforms.make_nstep_transform`, ``k = steps_to_next_obs``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase, TensorDictParams
from tensordict.nn import TensorDictModule, dispatch
from tensordict.utils import NestedKey
from torch import Tensor
from torchrl.objectives import DDPGLoss
from torchrl.objectives.utils import ValueEstimators, _cache_values, distance_loss

from s3rl_torchrl.objectives._common import next_key as _next
from s3rl_torchrl.objectives._common import parameter_containers
from s3rl_torchrl.objectives._lagrangian_buffer import LagrangianBufferMixin

__all__ = ["DDPGLagLoss"]

# What DDPGLoss clears the weak references of, and the cost critic's.
_PARAMETER_CONTAINERS = parameter_containers("actor", "value", "cost_value")


class DDPGLagLoss(LagrangianBufferMixin, DDPGLoss):
    r"""DDPG with Lagrangian cost penalties (FSRL's DDPG-Lag), TensorDict-native.

    A subclass of :class:`torchrl.objectives.DDPGLoss` that adds a cost critic (with its
    target), its TD loss and the Lagrangian actor loss (module docstring). The reward critic's
    loss is ``DDPGLoss.loss_value`` unchanged. ``lagrangian`` is a buffer of shape ``[m]`` set
    from outside, typically by a :class:`~s3rl_torchrl.objectives.PIDLagrangian` once per
    collect: ``loss.set_lagrangian(controller.update(mean_episode_cost))``.

    With ``lagrangian = 0`` the actor and reward-critic losses (values and gradients) are
    ``DDPGLoss``'s on the same networks and batch.

    Args:
        actor_network: deterministic actor ``observation -> "action"`` (e.g.
            :func:`~s3rl_torchrl.modules.build_deterministic_actor`).
        value_network: reward critic ``[observation, action] -> "state_action_value"``
            (``[..., 1]``).
        cost_value_network: cost critic ``[observation, action] ->
            "state_action_cost_value"`` (``[..., m]``, one output per cost; e.g.
            ``build_qvalue_network(..., num_outputs=m, out_key="state_action_cost_value")``).

    Keyword Args:
        num_costs: number of costs ``m`` (trailing dimension of ``("next", "cost")`` and of the
            cost critic's output). Defaults to 1.
        loss_function: critic regression loss (FSRL: ``"l2"``, the squared error).
        delay_actor: keep a target actor for the targets (FSRL: ``True``, its ``actor_old``).
        delay_value: keep target critics, reward and cost (FSRL: ``True``).
        rescaling: divide the actor loss by ``1 + sum(lagrangian)`` (FSRL: ``True``).
        lagrangian_init: initial ``lagrangian`` (float or ``m`` values, >= 0).
        separate_losses, reduction, use_prioritized_weights: as in ``DDPGLoss``.

    Keys (``loss.set_keys(...)``): those of ``DDPGLoss`` plus ``cost`` (read at
    ``("next", cost)``) and ``state_action_cost_value`` (the cost critic's output).

    The forward returns ``loss_actor``, ``loss_value`` (reward critic), ``loss_cost_value`` (cost
    critic), whose sum is what to minimise, ``DDPGLoss``'s diagnostics and ``reward_q`` (mean
    ``Q_r(s, mu(s))``), ``cost_q`` (``[m]``) and ``lagrangian`` (``[m]``). Set the discount with
    ``loss.make_value_estimator(gamma=...)`` (TD(0) only: n-step returns come from the buffer).
    """

    @dataclass
    class _AcceptedKeys(DDPGLoss._AcceptedKeys):
        """Tensordict keys of :class:`DDPGLagLoss`: ``DDPGLoss``'s plus the cost ones.

        Attributes:
            cost: cost entry, read at ``("next", cost)``, trailing dimension ``num_costs``.
            state_action_cost_value: output key of the cost critic.
        """

        cost: NestedKey = "cost"
        state_action_cost_value: NestedKey = "state_action_cost_value"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    SUPPORTED_VALUE_ESTIMATORS = (ValueEstimators.TD0,)
    _schedulable_buffers = frozenset(
        getattr(DDPGLoss, "_schedulable_buffers", frozenset()) | {"lagrangian"}
    )

    cost_value_network: TensorDictModule
    cost_value_network_params: TensorDictParams
    target_cost_value_network_params: TensorDictParams

    def __init__(
        self,
        actor_network: TensorDictModule,
        value_network: TensorDictModule,
        cost_value_network: TensorDictModule,
        *,
        num_costs: int = 1,
        loss_function: str = "l2",
        delay_actor: bool = True,
        delay_value: bool = True,
        rescaling: bool = True,
        lagrangian_init: float | Sequence[float] | Tensor = 0.0,
        separate_losses: bool = False,
        reduction: str | None = None,
        use_prioritized_weights: str | bool = "auto",
    ) -> None:
        if isinstance(num_costs, bool) or not isinstance(num_costs, int) or num_costs < 1:
            raise ValueError(
                f"num_costs must be an integer >= 1, got {num_costs!r} (for no cost critic use "
                "torchrl.objectives.DDPGLoss)."
            )
        if cost_value_network is None:
            raise ValueError("DDPGLagLoss needs a cost_value_network (a cost Q critic).")
        super().__init__(
            actor_network,
            value_network,
            loss_function=loss_function,
            delay_actor=delay_actor,
            delay_value=delay_value,
            separate_losses=separate_losses,
            reduction=reduction,
            use_prioritized_weights=use_prioritized_weights,
        )
        self.convert_to_functional(
            cost_value_network,
            "cost_value_network",
            create_target_params=delay_value,
            compare_against=list(actor_network.parameters()) if separate_losses else None,
        )
        self.num_costs = num_costs
        self.rescaling = bool(rescaling)
        device = next(iter(self.value_network_params.values(True, True))).device
        self._init_lagrangian(lagrangian_init, device=device)
        self.cost_exclusive_keys = set(self.cost_value_network.in_keys) - (
            set(self.actor_in_keys) | set(self.actor_network.out_keys)
        )

    def _set_in_keys(self):
        super()._set_in_keys()
        keys = set(self._in_keys) | {
            *self.cost_value_network.in_keys,
            *[_next(key) for key in self.cost_value_network.in_keys],
            _next(self.tensor_keys.cost),
        }
        self._in_keys = sorted(keys, key=str)

    @property
    @_cache_values
    def _cached_detached_cost_value_params(self):
        return self.cost_value_network_params.detach()

    def _get_cost(self, tensordict: TensorDictBase) -> Tensor:
        key = _next(self.tensor_keys.cost)
        cost = tensordict.get(key)
        batch = tuple(tensordict.batch_size)
        if cost.shape == batch and self.num_costs == 1:
            cost = cost.unsqueeze(-1)
        if tuple(cost.shape) != (*batch, self.num_costs):
            raise ValueError(
                f"DDPGLagLoss was built with num_costs={self.num_costs}: {key} must have shape "
                f"{(*batch, self.num_costs)}, got {tuple(cost.shape)}."
            )
        return cost

    def cost_targets(self, tensordict: TensorDictBase) -> Tensor:
        """``y_c = c + gamma^k (1 - terminated) Q_c'(s', mu'(s'))``, ``[*B, m]``, no gradient.

        torchrl's TD(0) estimate (the reward critic's estimator), one column per cost.
        """
        keys = self.tensor_keys
        cost = self._get_cost(tensordict)
        with torch.no_grad():
            next_td = tensordict.get("next").select(
                *self.actor_in_keys, *self.cost_exclusive_keys, strict=False
            )
            next_td = next_td.copy()
            with self.target_actor_network_params.to_module(
                self.actor_network, preserve_module_state=False
            ):
                self.actor_network(next_td)
            with self.target_cost_value_network_params.to_module(
                self.cost_value_network, preserve_module_state=False
            ):
                self.cost_value_network(next_td)
            next_value = next_td.get(keys.state_action_cost_value)
            estimator = self.value_estimator
            est_keys = estimator.tensor_keys
            terminated = tensordict.get(_next(keys.terminated), None)
            if terminated is None:
                terminated = tensordict.get(_next(keys.done))
            shape = cost.shape
            flags = terminated.reshape(*tensordict.batch_size, 1).expand(shape)
            entries = {
                _next(est_keys.reward): cost.to(next_value.dtype),
                _next(est_keys.terminated): flags,
                _next(est_keys.done): flags,
            }
            steps = tensordict.get(est_keys.steps_to_next_obs, None)
            if steps is not None:
                entries[est_keys.steps_to_next_obs] = steps.reshape(
                    *tensordict.batch_size, 1
                ).expand(shape)
            td = TensorDict(entries, batch_size=tensordict.batch_size)
            return estimator.value_estimate(td, next_value=next_value)

    def loss_cost_value(self, tensordict: TensorDictBase) -> tuple[Tensor, dict]:
        """Cost-critic TD loss, summed over the costs (FSRL sums its critics' losses)."""
        weights = self._maybe_get_priority_weight(tensordict)
        td_copy = tensordict.select(*self.cost_value_network.in_keys, strict=False).detach()
        with self.cost_value_network_params.to_module(
            self.cost_value_network, preserve_module_state=False
        ):
            self.cost_value_network(td_copy)
        pred = td_copy.get(self.tensor_keys.state_action_cost_value)
        target = self.cost_targets(tensordict)
        loss = distance_loss(pred, target, loss_function=self.loss_function).sum(-1)
        loss = self._reduce_loss(loss, tensordict=tensordict, weights=weights)
        metadata = {"pred_cost_value": pred.detach(), "target_cost_value": target}
        return loss, metadata

    def critic_loss(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Both critic losses (``loss_value``, ``loss_cost_value``), for FSRL's update order."""
        loss_value, _ = self.loss_value(tensordict)
        loss_cost_value, _ = self.loss_cost_value(tensordict)
        return TensorDict(
            {"loss_value": loss_value, "loss_cost_value": loss_cost_value}, batch_size=[]
        )

    def loss_actor(self, tensordict: TensorDictBase) -> tuple[Tensor, dict]:
        """Lagrangian actor loss; metadata ``reward_q`` and ``cost_q`` (``[m]``), detached."""
        weights = self._maybe_get_priority_weight(tensordict)
        td_copy = tensordict.select(
            *self.actor_in_keys,
            *self.value_exclusive_keys,
            *self.cost_exclusive_keys,
            strict=False,
        ).detach()
        with self.actor_network_params.to_module(
            self.actor_network, preserve_module_state=False
        ):
            td_copy = self.actor_network(td_copy)
        # Detached critic parameters: the actor loss must not move the critics.
        with self._cached_detached_value_params.to_module(
            self.value_network, preserve_module_state=False
        ):
            td_copy = self.value_network(td_copy)
        with self._cached_detached_cost_value_params.to_module(
            self.cost_value_network, preserve_module_state=False
        ):
            td_copy = self.cost_value_network(td_copy)
        q_reward = td_copy.get(self.tensor_keys.state_action_value).squeeze(-1)
        q_cost = td_copy.get(self.tensor_keys.state_action_cost_value)
        loss_actor = -q_reward + (q_cost * self.lagrangian).sum(-1)
        if self.rescaling:
            loss_actor = loss_actor / (1.0 + self.lagrangian.sum())
        loss_actor = self._reduce_loss(loss_actor, tensordict=tensordict, weights=weights)
        metadata = {
            "reward_q": q_reward.detach().mean(),
            "cost_q": q_cost.detach().reshape(-1, self.num_costs).mean(0),
        }
        self._clear_weakrefs(tensordict, loss_actor, *_PARAMETER_CONTAINERS)
        return loss_actor, metadata

    @dispatch
    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        loss_value, metadata = self.loss_value(tensordict)
        loss_cost_value, _ = self.loss_cost_value(tensordict)
        loss_actor, metadata_actor = self.loss_actor(tensordict)
        td_out = TensorDict(
            {
                "loss_actor": loss_actor,
                "loss_value": loss_value,
                "loss_cost_value": loss_cost_value,
                **metadata,
                **metadata_actor,
                "lagrangian": self.lagrangian.detach().clone(),
            },
            batch_size=[],
        )
        self._clear_weakrefs(tensordict, td_out, *_PARAMETER_CONTAINERS)
        return td_out
