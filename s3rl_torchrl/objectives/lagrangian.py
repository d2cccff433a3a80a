"""Lagrange multiplier controllers for m cost constraints ``J_i <= d_i``.

Each controller is a small ``nn.Module`` whose state lives in buffers (so ``state_dict`` /
``load_state_dict`` checkpoint it) with one method that matters::

    lam = controller.update(mean_episode_cost)   # once per collect, before the gradient steps
    loss.lagrangian = lam                        # SACLagLoss reads it in the actor loss

``mean_episode_cost`` is the mean undiscounted episode cost ``J`` of the training episodes just
collected: a number for one cost, or ``m`` values.

- :class:`PIDLagrangian`: Stooke et al. (2020) in FSRL's form by default, with the rlpyt/OmniSafe
  variants behind flags.
- :class:`LearnedLagrangian`: gradient ascent on ``lambda * (J - d)`` with Adam, clamped at 0
  (OmniSafe's SACLag).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Literal

import torch
from torch import Tensor, nn

__all__ = ["LagrangianController", "LearnedLagrangian", "PIDLagrangian"]

_HISTORY_INIT_CHOICES = ("limit", "zero")


def _as_vector(value, name: str, num: int | None = None) -> Tensor:
    """``value`` as a float64 vector of ``num`` entries (a number is broadcast when ``num`` set)."""
    if isinstance(value, Tensor):
        tensor = value.detach().to(dtype=torch.float64, device="cpu")
    else:
        try:
            tensor = torch.as_tensor(value, dtype=torch.float64)
        except (TypeError, ValueError, RuntimeError) as err:
            raise TypeError(
                f"{name} must be a number or a sequence of numbers, got {value!r}."
            ) from err
    if tensor.ndim == 0:
        tensor = tensor.reshape(1) if num is None else tensor.expand(num).clone()
    if tensor.ndim != 1 or tensor.numel() == 0:
        raise ValueError(
            f"{name} must be a number or a 1-D sequence, got shape {tuple(tensor.shape)}."
        )
    if num is not None and tensor.numel() != num:
        raise ValueError(f"{name} has {tensor.numel()} entries, expected {num} (one per cost).")
    return tensor


def _check_gain(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}.")
    return value


class LagrangianController(nn.Module):
    """Base class: per-cost limits ``cost_limit`` ([m]) and the current multipliers.

    Subclasses implement :meth:`_update` (float64 ``J`` of shape ``[m]`` -> new multipliers).
    """

    def __init__(self, cost_limit: float | Sequence[float] | Tensor, num_costs: int | None = None):
        super().__init__()
        if num_costs is not None and (
            isinstance(num_costs, bool) or not isinstance(num_costs, int) or num_costs < 1
        ):
            raise ValueError(f"num_costs must be an integer >= 1, got {num_costs!r}.")
        limit = _as_vector(cost_limit, "cost_limit", num_costs)
        if not bool(torch.isfinite(limit).all()) or bool((limit < 0).any()):
            raise ValueError(
                f"cost_limit must be finite and >= 0 (a per-episode cost budget), got "
                f"{limit.tolist()}."
            )
        self.num_costs = limit.numel()
        self.register_buffer("cost_limit", limit)
        self.register_buffer("num_updates", torch.zeros((), dtype=torch.long))

    @property
    def lagrangian(self) -> Tensor:
        """Current multipliers, shape ``[m]`` (float64; ``SACLagLoss`` converts on assignment)."""
        raise NotImplementedError

    def _update(self, cost: Tensor) -> Tensor:
        raise NotImplementedError

    def update(self, mean_episode_cost: float | Sequence[float] | Tensor) -> Tensor:
        """One controller step from the mean episode cost ``J`` (``m`` values); returns lambda.

        Raises ``ValueError`` on a NaN/inf cost (e.g. a collect in which no episode finished:
        skip the update then).
        """
        cost = _as_vector(mean_episode_cost, "mean_episode_cost")
        if cost.numel() != self.num_costs:
            raise ValueError(
                f"mean_episode_cost has {cost.numel()} entries but the controller has "
                f"{self.num_costs} cost limit(s)."
            )
        if not bool(torch.isfinite(cost).all()):
            raise ValueError(
                f"mean_episode_cost must be finite, got {cost.tolist()} (no finished episode? "
                "skip the update)."
            )
        lam = self._update(cost)
        self.num_updates += 1
        return lam.detach().clone()

    def extra_repr(self) -> str:
        return f"num_costs={self.num_costs}, cost_limit={self.cost_limit.tolist()}"


class PIDLagrangian(LagrangianController):
    r"""PID Lagrangian (Stooke, Achiam & Abbeel 2020), FSRL's form by default.

    Per cost, with ``e = J - d`` (all state starts at 0)::

        P      = error_ema * P + (1 - error_ema) * e           # error_ema = 0: P = e
        I      = max(0, I + e)          ;  I_term = ki * I     # FSRL
        I      = max(0, I + ki * e)     ;  I_term = I          # ki_inside_integral (rlpyt)
        C      = cost_ema * C + (1 - cost_ema) * J             # cost_ema = 0: C = J
        D      = max(0, C - C_{t - derivative_delay})          # history starts at d or 0
        lambda = max(0, kp * P + I_term + kd * D)  [min penalty_max]

    With the defaults this is exactly FSRL's ``LagrangianOptimizer``: ``D = max(0, e - e_prev)``
    with ``e_prev = 0`` at the start (``derivative_history_init="limit"`` puts ``d`` in the cost
    history, i.e. an error of 0). The rlpyt/OmniSafe controller is ``error_ema=0.95,
    cost_ema=0.95, derivative_delay=10, ki_inside_integral=True,
    derivative_history_init="zero"`` (+ ``penalty_max=100``, which OmniSafe applies only
    without its ``sum_norm``/``diff_norm``).

    Args:
        kp, ki, kd: gains (paper/FSRL: 0.05, 0.0005, 0.1).
        cost_limit: per-episode cost limit ``d``: a number or one per cost.

    Keyword Args:
        num_costs: number of costs ``m`` (broadcasts a scalar ``cost_limit``).
        ki_inside_integral: accumulate ``ki * e`` (rlpyt) instead of ``e`` (FSRL).
        error_ema: EMA coefficient of the proportional error, in ``[0, 1)``.
        cost_ema: EMA coefficient of the cost used by the derivative, in ``[0, 1)``.
        derivative_delay: the derivative compares with the cost ``derivative_delay`` updates ago.
        derivative_history_init: ``"limit"`` (FSRL: the history starts at ``d``) or ``"zero"``
            (rlpyt/OmniSafe: it starts at 0).
        penalty_max: upper bound of lambda (``None``: no bound).
        lagrangian_init: initial multiplier; seeds the integral term (OmniSafe's
            ``lagrangian_multiplier_init``) and is what :attr:`lagrangian` returns before the
            first update.
    """

    def __init__(
        self,
        kp: float = 0.05,
        ki: float = 0.0005,
        kd: float = 0.1,
        cost_limit: float | Sequence[float] | Tensor = 10.0,
        *,
        num_costs: int | None = None,
        ki_inside_integral: bool = False,
        error_ema: float = 0.0,
        cost_ema: float = 0.0,
        derivative_delay: int = 1,
        derivative_history_init: Literal["limit", "zero"] = "limit",
        penalty_max: float | None = None,
        lagrangian_init: float | Sequence[float] | Tensor = 0.0,
    ):
        super().__init__(cost_limit, num_costs)
        self.kp, self.ki, self.kd = (
            _check_gain(n, v) for n, v in (("kp", kp), ("ki", ki), ("kd", kd))
        )
        for name, value in (("error_ema", error_ema), ("cost_ema", cost_ema)):
            if not 0.0 <= float(value) < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {value!r}.")
        if (
            isinstance(derivative_delay, bool)
            or not isinstance(derivative_delay, int)
            or (derivative_delay < 1)
        ):
            raise ValueError(f"derivative_delay must be an integer >= 1, got {derivative_delay!r}.")
        if derivative_history_init not in _HISTORY_INIT_CHOICES:
            raise ValueError(
                f"Unknown derivative_history_init {derivative_history_init!r}; valid choices are "
                f"{', '.join(_HISTORY_INIT_CHOICES)}."
            )
        if penalty_max is not None and not float(penalty_max) > 0:
            raise ValueError(f"penalty_max must be > 0 or None, got {penalty_max!r}.")
        self.ki_inside_integral = bool(ki_inside_integral)
        self.error_ema = float(error_ema)
        self.cost_ema = float(cost_ema)
        self.derivative_delay = derivative_delay
        self.derivative_history_init = derivative_history_init
        self.penalty_max = None if penalty_max is None else float(penalty_max)

        m = self.num_costs
        init = _as_vector(lagrangian_init, "lagrangian_init", m)
        if bool((init < 0).any()) or not bool(torch.isfinite(init).all()):
            raise ValueError(f"lagrangian_init must be finite and >= 0, got {init.tolist()}.")
        if self.ki_inside_integral:
            integral = init.clone()
        elif bool((init > 0).any()):
            if self.ki == 0:
                raise ValueError("lagrangian_init > 0 needs ki > 0 (it seeds the integral term).")
            integral = init / self.ki
        else:
            integral = torch.zeros(m, dtype=torch.float64)
        history = self.cost_limit if derivative_history_init == "limit" else torch.zeros(m)
        # State in float64: the integral sums thousands of updates.
        self.register_buffer("integral", integral)
        self.register_buffer("error", torch.zeros(m, dtype=torch.float64))
        self.register_buffer("smoothed_cost", history.clone().to(torch.float64))
        self.register_buffer(
            "cost_history", history.to(torch.float64).expand(derivative_delay, m).clone()
        )
        self.register_buffer("_lagrangian", init.clone())

    @property
    def lagrangian(self) -> Tensor:
        return self._lagrangian.clone()

    def _update(self, cost: Tensor) -> Tensor:
        e = cost - self.cost_limit
        self.error.mul_(self.error_ema).add_((1.0 - self.error_ema) * e)
        if self.ki_inside_integral:
            self.integral.copy_((self.integral + self.ki * e).clamp_min(0.0))
            i_term = self.integral
        else:
            self.integral.copy_((self.integral + e).clamp_min(0.0))
            i_term = self.ki * self.integral
        if self.cost_ema == 0.0:
            self.smoothed_cost.copy_(cost)
        else:
            self.smoothed_cost.mul_(self.cost_ema).add_((1.0 - self.cost_ema) * cost)
        derivative = (self.smoothed_cost - self.cost_history[0]).clamp_min(0.0)
        self.cost_history.copy_(torch.cat([self.cost_history[1:], self.smoothed_cost[None]], 0))
        lam = (self.kp * self.error + i_term + self.kd * derivative).clamp_min(0.0)
        if self.penalty_max is not None:
            lam = lam.clamp_max(self.penalty_max)
        self._lagrangian.copy_(lam)
        return lam

    def extra_repr(self) -> str:
        return (
            f"{super().extra_repr()}, kp={self.kp}, ki={self.ki}, kd={self.kd}, "
            f"ki_inside_integral={self.ki_inside_integral}, error_ema={self.error_ema}, "
            f"cost_ema={self.cost_ema}, derivative_delay={self.derivative_delay}, "
            f"penalty_max={self.penalty_max}"
        )


class LearnedLagrangian(LagrangianController):
    """Lambda learned by gradient ascent on ``lambda * (J - d)`` with Adam, clamped to
    ``[0, upper_bound]`` (OmniSafe's ``Lagrange``, used by its SACLag).

    Each :meth:`update` is one Adam step on ``-sum_i lambda_i (J_i - d_i)``. The Adam state is
    part of ``state_dict``.

    Args:
        cost_limit: per-episode cost limit ``d``: a number or one per cost.

    Keyword Args:
        num_costs: number of costs ``m`` (broadcasts a scalar ``cost_limit``).
        lr: Adam learning rate (OmniSafe SACLag: 0.001).
        lagrangian_init: initial lambda (OmniSafe: 0.001).
        upper_bound: optional upper clamp.
        betas, eps: Adam's.
    """

    def __init__(
        self,
        cost_limit: float | Sequence[float] | Tensor = 10.0,
        *,
        num_costs: int | None = None,
        lr: float = 1e-3,
        lagrangian_init: float | Sequence[float] | Tensor = 1e-3,
        upper_bound: float | None = None,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ):
        super().__init__(cost_limit, num_costs)
        if not (math.isfinite(float(lr)) and float(lr) > 0):
            raise ValueError(f"lr must be a finite number > 0, got {lr!r}.")
        if upper_bound is not None and not float(upper_bound) > 0:
            raise ValueError(f"upper_bound must be > 0 or None, got {upper_bound!r}.")
        init = _as_vector(lagrangian_init, "lagrangian_init", self.num_costs)
        if bool((init < 0).any()) or not bool(torch.isfinite(init).all()):
            raise ValueError(f"lagrangian_init must be finite and >= 0, got {init.tolist()}.")
        self.upper_bound = None if upper_bound is None else float(upper_bound)
        self.multiplier = nn.Parameter(init.to(torch.float32))
        self.optimizer = torch.optim.Adam([self.multiplier], lr=float(lr), betas=betas, eps=eps)

    @property
    def lagrangian(self) -> Tensor:
        return self.multiplier.detach().to(torch.float64).clone()

    def _update(self, cost: Tensor) -> Tensor:
        gap = (cost - self.cost_limit).to(self.multiplier.dtype)
        self.optimizer.zero_grad(set_to_none=True)
        with torch.enable_grad():
            loss = -(self.multiplier * gap).sum()
            loss.backward()
        self.optimizer.step()
        with torch.no_grad():
            self.multiplier.clamp_(0.0, self.upper_bound)
        return self.lagrangian

    def get_extra_state(self):
        return {"optimizer": self.optimizer.state_dict()}

    def set_extra_state(self, state) -> None:
        # Adam's load_state_dict keeps the given tensors when dtype and device match: copy, so
        # that loading from another live controller does not share its moments.
        self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))

    def extra_repr(self) -> str:
        lr = self.optimizer.param_groups[0]["lr"]
        return f"{super().extra_repr()}, lr={lr}, upper_bound={self.upper_bound}"
