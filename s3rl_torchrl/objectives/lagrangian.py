"""Lagrange multiplier controllers for m cost constraints ``J_i <= d_i``, and when they update.

Each controller is a small ``nn.Module`` (``state_dict`` / ``load_state_dict`` checkpoint it)
with one method that matters::

    lam = controller.update(mean_episode_cost)   # J: the mean episode cost (m values)
    loss.lagrangian = lam                        # SACLagLoss reads it in the actor loss

- :class:`PIDLagrangian`: Stooke et al. (2020) in FSRL's form by default, with the rlpyt/OmniSafe
  variants behind flags.
- :class:`LearnedLagrangian`: gradient ascent on ``lambda * (J - d)`` with Adam, clamped at 0
  (OmniSafe's SACLag).

How often ``update`` runs and from which episodes is :class:`LagrangianUpdater`'s business:

- ``cadence="collect"`` (FSRL, the paper): once per collected batch in which episodes ended,
  from the mean cost of those episodes, before that batch's gradient steps;
- ``cadence="step"`` (OmniSafe): after every gradient step, from the mean cost of the last
  ``window`` finished training episodes (:class:`EpisodeCostWindow`).

Both cadences keep lambda at its initial value until more than ``warmup_frames`` frames have
been collected. With ``eval_window=K > 0`` the controller follows, per cost, the larger of that
training mean and the mean cost of the last ``K`` deterministic evaluation episodes
(:meth:`LagrangianUpdater.observe_evaluation`): the training episodes come from the stochastic,
exploring policy, while a run delivers its deterministic policy, whose cost can sit on either
side of the training cost (docs/objectives.md, "Aiming at the delivered policy"). The controllers' state is a handful of Python floats (checkpointed as the
modules' extra state): a per-step update then costs microseconds, where the same arithmetic on
one-element tensors cost 0.13 ms (PID) and 0.36 ms (Adam through ``torch.optim``) per call,
1-4% of a gradient step (docs/benchmarks.md).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any, Literal

import torch
from torch import Tensor, nn

__all__ = [
    "LAGRANGIAN_CADENCES",
    "EpisodeCostWindow",
    "LagrangianController",
    "LagrangianUpdater",
    "LearnedLagrangian",
    "PIDLagrangian",
]

_HISTORY_INIT_CHOICES = ("limit", "zero")
LAGRANGIAN_CADENCES = ("collect", "step")


def _as_floats(value, name: str, num: int | None = None) -> list[float]:
    """``value`` as a list of ``num`` floats (a number is broadcast when ``num`` is set)."""
    if isinstance(value, Tensor):
        value = value.detach().reshape(-1).tolist() if value.ndim else value.item()
    if isinstance(value, int | float):
        values = [float(value)] * (1 if num is None else num)
    else:
        try:
            values = [float(v) for v in value]
        except (TypeError, ValueError) as err:
            raise TypeError(
                f"{name} must be a number or a sequence of numbers, got {value!r}."
            ) from err
        if not values:
            raise ValueError(f"{name} must be a number or a non-empty 1-D sequence, got [].")
    if num is not None and len(values) != num:
        raise ValueError(f"{name} has {len(values)} entries, expected {num} (one per cost).")
    return values


def _check_gain(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}.")
    return value


def _check_init(values: list[float]) -> list[float]:
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f"lagrangian_init must be finite and >= 0, got {values}.")
    return values


def _tensor(values: list[float]) -> Tensor:
    return torch.tensor(values, dtype=torch.float64)


class LagrangianController(nn.Module):
    """Base class: per-cost limits ``cost_limit`` ([m]) and the current multipliers.

    Subclasses keep their state in Python floats, name it in ``_state_names`` (what
    ``state_dict`` saves) and implement :meth:`_update` (``J`` as ``m`` floats -> the new
    multipliers as ``m`` floats).
    """

    _state_names: tuple[str, ...] = ()

    def __init__(self, cost_limit: float | Sequence[float] | Tensor, num_costs: int | None = None):
        super().__init__()
        if num_costs is not None and (
            isinstance(num_costs, bool) or not isinstance(num_costs, int) or num_costs < 1
        ):
            raise ValueError(f"num_costs must be an integer >= 1, got {num_costs!r}.")
        limit = _as_floats(cost_limit, "cost_limit", num_costs)
        if not all(math.isfinite(v) and v >= 0 for v in limit):
            raise ValueError(
                f"cost_limit must be finite and >= 0 (a per-episode cost budget), got {limit}."
            )
        self.num_costs = len(limit)
        self._cost_limit = limit
        self._lagrangian = [0.0] * self.num_costs
        self.num_updates = 0

    @property
    def cost_limit(self) -> Tensor:
        """Per-episode cost limits ``d``, shape ``[m]`` (float64)."""
        return _tensor(self._cost_limit)

    @property
    def lagrangian(self) -> Tensor:
        """Current multipliers, shape ``[m]`` (float64; ``SACLagLoss`` converts on assignment)."""
        return _tensor(self._lagrangian)

    def _update(self, cost: list[float]) -> list[float]:
        raise NotImplementedError

    def update(self, mean_episode_cost: float | Sequence[float] | Tensor) -> Tensor:
        """One controller step from the mean episode cost ``J`` (``m`` values); returns lambda.

        Raises ``ValueError`` on a NaN/inf cost (e.g. a collect in which no episode finished:
        skip the update then).
        """
        return _tensor(self.update_floats(_as_floats(mean_episode_cost, "mean_episode_cost")))

    def update_floats(self, mean_episode_cost: list[float]) -> list[float]:
        """:meth:`update` on a list of ``m`` floats, returning floats: the per-step path, without
        the tensor conversions (a few microseconds)."""
        cost = mean_episode_cost
        if len(cost) != self.num_costs:
            raise ValueError(
                f"mean_episode_cost has {len(cost)} entries but the controller has "
                f"{self.num_costs} cost limit(s)."
            )
        if not all(math.isfinite(c) for c in cost):
            raise ValueError(
                f"mean_episode_cost must be finite, got {cost} (no finished episode? skip the "
                "update)."
            )
        self._lagrangian = self._update(cost)
        self.num_updates += 1
        return list(self._lagrangian)

    # Checkpoints: the floats as the module's extra state (plain lists: weights_only loads them).
    def get_extra_state(self) -> dict[str, Any]:
        names = ("_lagrangian", "num_updates", *self._state_names)
        return {name: _copy(getattr(self, name)) for name in names}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        for name, value in state.items():
            setattr(self, name, _copy(value))

    def extra_repr(self) -> str:
        return f"num_costs={self.num_costs}, cost_limit={self._cost_limit}"


def _copy(value):
    return [_copy(v) for v in value] if isinstance(value, list | tuple) else value


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

    The gains are per update: once per collect (FSRL: 0.05, 0.0005, 0.1) they mean something
    else than after every gradient step (OmniSafe's SACPID: 1e-6, 1e-7, 1e-7), see
    ``docs/objectives.md``.

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

    _state_names = ("integral", "error", "smoothed_cost", "cost_history")

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
        init = _check_init(_as_floats(lagrangian_init, "lagrangian_init", m))
        if self.ki_inside_integral:
            integral = list(init)
        elif any(v > 0 for v in init):
            if self.ki == 0:
                raise ValueError("lagrangian_init > 0 needs ki > 0 (it seeds the integral term).")
            integral = [v / self.ki for v in init]
        else:
            integral = [0.0] * m
        history = self._cost_limit if derivative_history_init == "limit" else [0.0] * m
        self.integral = integral
        self.error = [0.0] * m
        self.smoothed_cost = list(history)
        # Oldest first: the derivative compares with cost_history[0].
        self.cost_history = [list(history) for _ in range(derivative_delay)]
        self._lagrangian = list(init)

    def _update(self, cost: list[float]) -> list[float]:
        lam = []
        newest = []
        for i, (j, d) in enumerate(zip(cost, self._cost_limit)):
            e = j - d
            self.error[i] = self.error_ema * self.error[i] + (1.0 - self.error_ema) * e
            if self.ki_inside_integral:
                self.integral[i] = max(0.0, self.integral[i] + self.ki * e)
                i_term = self.integral[i]
            else:
                self.integral[i] = max(0.0, self.integral[i] + e)
                i_term = self.ki * self.integral[i]
            if self.cost_ema == 0.0:
                self.smoothed_cost[i] = j
            else:
                self.smoothed_cost[i] = self.cost_ema * self.smoothed_cost[i] + (
                    1.0 - self.cost_ema
                ) * j
            derivative = max(0.0, self.smoothed_cost[i] - self.cost_history[0][i])
            newest.append(self.smoothed_cost[i])
            value = max(0.0, self.kp * self.error[i] + i_term + self.kd * derivative)
            lam.append(value if self.penalty_max is None else min(value, self.penalty_max))
        self.cost_history.pop(0)
        self.cost_history.append(newest)
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

    Each :meth:`update` is one Adam step (``torch.optim.Adam``'s update, written out for a
    handful of floats: the same numbers up to float32 rounding, tests/objectives) on the loss
    ``-sum_i lambda_i (J_i - d_i)``, whose gradient is ``-(J_i - d_i)``. With an error of
    constant sign Adam moves lambda by ``lr`` per update whatever its size, so ``lr`` is a rate
    per update: OmniSafe's SACLag uses 1e-5 per gradient step (``cadence="step"``).

    Args:
        cost_limit: per-episode cost limit ``d``: a number or one per cost.

    Keyword Args:
        num_costs: number of costs ``m`` (broadcasts a scalar ``cost_limit``).
        lr: Adam learning rate.
        lagrangian_init: initial lambda (OmniSafe: 0.001).
        upper_bound: optional upper clamp.
        betas, eps: Adam's.
    """

    _state_names = ("adam_step", "adam_mean", "adam_square")

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
        if not all(0.0 <= float(b) < 1.0 for b in betas) or not float(eps) > 0:
            raise ValueError(f"betas must be in [0, 1) and eps > 0, got {betas!r}, {eps!r}.")
        self.lr = float(lr)
        self.upper_bound = None if upper_bound is None else float(upper_bound)
        self.betas = (float(betas[0]), float(betas[1]))
        self.eps = float(eps)
        m = self.num_costs
        self._lagrangian = _check_init(_as_floats(lagrangian_init, "lagrangian_init", m))
        self.adam_step = 0
        self.adam_mean = [0.0] * m
        self.adam_square = [0.0] * m

    @property
    def multiplier(self) -> Tensor:
        """The learned multipliers (the same values as :attr:`lagrangian`)."""
        return self.lagrangian

    def _update(self, cost: list[float]) -> list[float]:
        beta1, beta2 = self.betas
        self.adam_step += 1
        correction1 = 1.0 - beta1**self.adam_step
        correction2 = math.sqrt(1.0 - beta2**self.adam_step)
        upper = math.inf if self.upper_bound is None else self.upper_bound
        lam = []
        for i, (j, d) in enumerate(zip(cost, self._cost_limit)):
            grad = d - j  # of -lambda (J - d)
            mean = self.adam_mean[i] = beta1 * self.adam_mean[i] + (1.0 - beta1) * grad
            square = self.adam_square[i] = beta2 * self.adam_square[i] + (1.0 - beta2) * grad**2
            step = self.lr / correction1 * mean / (math.sqrt(square) / correction2 + self.eps)
            lam.append(min(max(self._lagrangian[i] - step, 0.0), upper))
        return lam

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, lr={self.lr}, upper_bound={self.upper_bound}"


class EpisodeCostWindow(nn.Module):
    """The costs of the last ``size`` finished episodes and their mean (OmniSafe's
    ``window_lens``): what a per-step controller is fed. Checkpointed as extra state."""

    def __init__(self, size: int, num_costs: int = 1):
        super().__init__()
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"window size must be an integer >= 1, got {size!r}.")
        self.size, self.num_costs = size, num_costs
        self._costs: deque[list[float]] = deque(maxlen=size)
        self._mean: list[float] | None = None

    def __len__(self) -> int:
        return len(self._costs)

    def extend(self, episode_costs: Tensor | Sequence) -> None:
        """Add finished episodes' costs, oldest first: ``[episodes, m]`` (or ``[episodes]``)."""
        if isinstance(episode_costs, Tensor):
            episode_costs = episode_costs.detach().reshape(-1, self.num_costs).tolist()
        rows = [_as_floats(row, "episode cost", self.num_costs) for row in episode_costs]
        if not rows:
            return
        self._costs.extend(rows)
        count = len(self._costs)
        self._mean = [sum(column) / count for column in zip(*self._costs)]

    def mean(self) -> list[float] | None:
        """Mean cost per cost signal over the window, ``None`` before any episode ended."""
        return None if self._mean is None else list(self._mean)

    def get_extra_state(self) -> dict[str, Any]:
        return {"costs": [list(row) for row in self._costs]}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        self._costs.clear()
        self._mean = None
        self.extend(state["costs"])

    def extra_repr(self) -> str:
        return f"size={self.size}, num_costs={self.num_costs}"


class LagrangianUpdater(nn.Module):
    """When a controller updates lambda, from which episodes, and where lambda goes.

    Call :meth:`observe` once per collected batch with the costs of the training episodes that
    ended in it, and :meth:`after_gradient_step` after each gradient step; lambda is written in
    place into ``loss.lagrangian`` (a buffer, so a compiled loss reads the new value without
    recompiling).

    Args:
        controller: a :class:`LagrangianController`.
        loss: a loss with a ``lagrangian`` buffer (``SACLagLoss``, ``DDPGLagLoss``, ...).

    Keyword Args:
        cadence: ``"collect"`` (FSRL, the paper: one update per batch in which episodes ended,
            from their mean cost) or ``"step"`` (OmniSafe: one update after every gradient step,
            from the mean cost of the last ``window`` finished episodes).
        window: episodes in the running window (``cadence="step"`` only).
        warmup_frames: lambda keeps its initial value until more than this many frames have
            been collected (OmniSafe's ``warmup_epochs`` x ``steps_per_epoch``).
        eval_window: ``0`` (the training episodes alone) or the number of deterministic
            evaluation episodes whose mean cost the controller also follows: ``J`` is then, per
            cost, the larger of the training mean and that mean (once an evaluation has run).

    ``state_dict`` holds the controller's state and the windows.
    """

    def __init__(
        self,
        controller: LagrangianController,
        loss: nn.Module,
        *,
        cadence: Literal["collect", "step"] = "collect",
        window: int = 10,
        warmup_frames: int = 0,
        eval_window: int = 0,
    ):
        super().__init__()
        if cadence not in LAGRANGIAN_CADENCES:
            raise ValueError(
                f"Unknown cadence {cadence!r}; valid choices are {', '.join(LAGRANGIAN_CADENCES)}."
            )
        if isinstance(warmup_frames, bool) or not isinstance(warmup_frames, int) or (
            warmup_frames < 0
        ):
            raise ValueError(f"warmup_frames must be an integer >= 0, got {warmup_frames!r}.")
        self.controller = controller
        self.cadence = cadence
        self.warmup_frames = warmup_frames
        self.window = EpisodeCostWindow(window, controller.num_costs) if cadence == "step" else None
        if isinstance(eval_window, bool) or not isinstance(eval_window, int) or eval_window < 0:
            raise ValueError(f"eval_window must be an integer >= 0, got {eval_window!r}.")
        self.evaluation_window = (
            EpisodeCostWindow(eval_window, controller.num_costs) if eval_window else None
        )
        self._loss = [loss]  # a list: not a submodule (the loss is checkpointed on its own)
        self._frames = 0

    @property
    def lagrangian(self) -> Tensor:
        return self.controller.lagrangian

    @property
    def warming_up(self) -> bool:
        return self._frames <= self.warmup_frames

    def _set(self, lagrangian: list[float]) -> None:
        self._loss[0].set_lagrangian(lagrangian)

    def observe(self, episode_costs: Tensor, frames: int) -> list[float] | None:
        """A collected batch: the costs of the episodes that ended in it (``[episodes, m]``,
        possibly none) and the frames collected so far. Returns the ``J`` lambda follows now
        (``collect``: the batch's mean, if it updated; ``step``: the window's mean)."""
        self._frames = frames
        if self.cadence == "step":
            self.window.extend(episode_costs)
            return self.signal(self.window.mean())
        if episode_costs.shape[0] == 0 or self.warming_up:
            return None
        mean_cost = self.signal(episode_costs.double().mean(0).tolist())
        self._set(self.controller.update_floats(mean_cost))
        return mean_cost

    def observe_evaluation(self, episode_costs: Tensor | Sequence) -> None:
        """The costs of deterministic evaluation episodes (``[episodes, m]``, oldest first);
        kept only with ``eval_window > 0``, where they join the controller's signal."""
        if self.evaluation_window is not None:
            self.evaluation_window.extend(episode_costs)

    def signal(self, training_cost: list[float] | None) -> list[float] | None:
        """The ``J`` the controller follows, given the training episodes' mean cost: that mean,
        or with ``eval_window > 0`` per cost the larger of it and the evaluation window's mean
        (the training mean alone until an evaluation has run). None: no episode yet."""
        evaluation = None if self.evaluation_window is None else self.evaluation_window.mean()
        if training_cost is None or evaluation is None:
            return training_cost
        return [max(train, deterministic) for train, deterministic in zip(training_cost, evaluation)]

    def after_gradient_step(self) -> bool:
        """``step`` cadence: one controller update from the window. True if lambda updated."""
        if self.window is None or self.warming_up:
            return False
        mean_cost = self.signal(self.window.mean())
        if mean_cost is None:
            return False
        self._set(self.controller.update_floats(mean_cost))
        return True

    def get_extra_state(self) -> dict[str, Any]:
        return {"frames": self._frames}

    def set_extra_state(self, state: dict[str, Any]) -> None:
        self._frames = int(state["frames"])

    def extra_repr(self) -> str:
        return f"cadence={self.cadence}, warmup_frames={self.warmup_frames}"
