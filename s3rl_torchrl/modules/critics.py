"""Q-critic builders for :class:`~s3rl_torchrl.objectives.SACLagLoss` (and torchrl's ``SACLoss``).

The critics follow FSRL's SAC-Lagrangian: ``Q(s, a) = MLP(concat(s, a))`` with ReLU hidden layers,
orthogonal weights (gain 1) and zero biases. They share no parameters with the actor.

One builder call gives **one** Q-network. A loss needs several (a double critic for the reward,
one double critic per cost), so pass a *list* of independently built networks to the loss::

    reward_critics = [build_qvalue_network(obs_dim, act_dim) for _ in range(2)]
    cost_critics = [build_cost_qvalue_network(obs_dim, act_dim) for _ in range(2 * num_costs)]

A list keeps the orthogonal initialisation of every copy. Passing a single module also works, but
torchrl then copies it and resamples each copy uniformly within the template's weight range.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import MLP, ValueOperator

from s3rl_torchrl.modules.activation import ReLU

__all__ = [
    "COST_QVALUE_KEY",
    "COST_VALUE_KEY",
    "QVALUE_KEY",
    "VALUE_KEY",
    "build_cost_qvalue_network",
    "build_qvalue_network",
    "build_value_network",
    "init_orthogonal_",
]

QVALUE_KEY = "state_action_value"
COST_QVALUE_KEY = "state_action_cost_value"
VALUE_KEY = "state_value"  # what torchrl's ClipPPOLoss reads
COST_VALUE_KEY = "state_cost_value"  # what PPOLagLoss reads


def init_orthogonal_(module: nn.Module, gain: float = 1.0) -> nn.Module:
    """FSRL's initialisation: orthogonal weights and zero biases for every ``nn.Linear``."""
    for layer in module.modules():
        if isinstance(layer, nn.Linear):
            nn.init.orthogonal_(layer.weight, gain=gain)
            if layer.bias is not None:
                nn.init.zeros_(layer.bias)
    return module


def _check_dims(observation_dim: int, action_dim: int, hidden: Sequence[int], num_outputs: int):
    for name, value in (
        ("observation_dim", observation_dim),
        ("action_dim", action_dim),
        ("num_outputs", num_outputs),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}.")
    hidden = tuple(hidden)
    if any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in hidden):
        raise ValueError(f"hidden must be a sequence of positive integers, got {hidden!r}.")
    return hidden


def build_qvalue_network(
    observation_dim: int,
    action_dim: int,
    hidden: Sequence[int] = (128, 128),
    num_outputs: int = 1,
    *,
    out_key: str = QVALUE_KEY,
    observation_key: str = "observation",
    action_key: str = "action",
    activation_class: type[nn.Module] = ReLU,
    device: torch.device | str | None = None,
) -> TensorDictModule:
    """One Q-network ``[observation, action] -> out_key`` (shape ``[..., num_outputs]``).

    Args:
        observation_dim: size of the (flat) observation.
        action_dim: size of the action.
        hidden: hidden layer widths (FSRL and the paper: ``(128, 128)``).
        num_outputs: size of the output's trailing dimension; 1 for a scalar Q-value.
        out_key: output key; ``"state_action_value"`` is what torchrl's ``SACLoss`` reads.
        observation_key, action_key: input keys.
        activation_class: hidden activation (FSRL: ReLU; default :class:`~s3rl_torchrl.modules.ReLU`,
            ``nn.ReLU`` that stays fast under ``torch.compile``).
        device: where to create the parameters.
    """
    hidden = _check_dims(observation_dim, action_dim, hidden, num_outputs)
    # torchrl's MLP concatenates its positional inputs, i.e. Q(concat(s, a)) as in FSRL.
    mlp = MLP(
        in_features=observation_dim + action_dim,
        out_features=num_outputs,
        num_cells=list(hidden),
        activation_class=activation_class,
        device=device,
    )
    init_orthogonal_(mlp)
    return ValueOperator(mlp, in_keys=[observation_key, action_key], out_keys=[out_key])


def build_cost_qvalue_network(
    observation_dim: int,
    action_dim: int,
    hidden: Sequence[int] = (128, 128),
    *,
    out_key: str = COST_QVALUE_KEY,
    observation_key: str = "observation",
    action_key: str = "action",
    activation_class: type[nn.Module] = ReLU,
    device: torch.device | str | None = None,
) -> TensorDictModule:
    """One cost Q-network ``[observation, action] -> "state_action_cost_value"`` (``[..., 1]``).

    Each network estimates one cost; :class:`~s3rl_torchrl.objectives.SACLagLoss` with ``m``
    costs holds ``2 * m`` of them (a double critic per cost, ordered ``[cost 0 net 0, cost 0 net
    1, cost 1 net 0, ...]``), each with its own MLP as in FSRL. With the same architecture as the
    reward critic, the loss evaluates reward and cost critics in one vmapped call.
    """
    return build_qvalue_network(
        observation_dim,
        action_dim,
        hidden,
        1,
        out_key=out_key,
        observation_key=observation_key,
        action_key=action_key,
        activation_class=activation_class,
        device=device,
    )


def build_value_network(
    observation_dim: int,
    hidden: Sequence[int] = (128, 128),
    *,
    out_key: str = VALUE_KEY,
    observation_key: str = "observation",
    activation_class: type[nn.Module] = ReLU,
    device: torch.device | str | None = None,
) -> TensorDictModule:
    """One state-value network ``observation -> out_key`` (``[..., 1]``) for PPO(-Lag).

    FSRL's PPO-Lag critics (``fsrl/agent/ppo_lag_agent.py``: one ``Critic`` per signal over a
    ``Net`` of ``hidden_sizes``) with the same orthogonal initialisation as the Q-critics; pass
    ``out_key=COST_VALUE_KEY`` for the cost value network of
    :class:`~s3rl_torchrl.objectives.PPOLagLoss`.
    """
    hidden = _check_dims(observation_dim, 1, hidden, 1)
    mlp = MLP(
        in_features=observation_dim,
        out_features=1,
        num_cells=list(hidden),
        activation_class=activation_class,
        device=device,
    )
    init_orthogonal_(mlp)
    return ValueOperator(mlp, in_keys=[observation_key], out_keys=[out_key])
