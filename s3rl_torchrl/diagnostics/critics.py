"""Are the critics sound, and which term drives the policy? Per-epoch diagnostics of the SAC
family's critics and actor loss (docs/objectives.md, "Critic diagnostics").

- :class:`RecentEpisodes` keeps the last few *finished* training episodes, whole, from the
  collected batches (an episode spans several batches: each env's unfinished steps are carried
  to the next batch).
- :func:`discounted_returns` is each step's discounted return within its episode, the Monte
  Carlo value a critic trained with the same ``gamma`` estimates.
- :func:`critic_calibration` holds the reward and cost critics, read as the loss reads them, at
  the stored ``(s_t, a_t)`` of those episodes against their returns: a cost critic below 0 or
  far from the costs that followed shows here.
- :func:`actor_gradient_norms` is the norm of the actor's gradient from each term of its loss
  (entropy, reward, ``lambda * Q_c``) on one replay batch.

Why recent episodes and not the replay buffer's labels: a critic estimates the value of the
*current* policy, and the buffer holds up to 100 episodes of older ones; and a label written when
a batch is stored stops at the batch's end (with 1000-frame batches over 10 envs, 100 steps,
about the horizon ``1 / (1 - gamma)`` of ``gamma = 0.99``).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

__all__ = [
    "RecentEpisodes",
    "actor_gradient_norms",
    "critic_calibration",
    "discounted_returns",
]

#: What an episode keeps: the critic's inputs and the signals and flags of each step.
EPISODE_KEYS = (
    "observation",
    "action",
    ("next", "reward"),
    ("next", "cost"),
    ("next", "done"),
    ("next", "terminated"),
)


class RecentEpisodes:
    """The last ``capacity`` finished training episodes, whole.

    :meth:`extend` takes each collected batch ``[*envs, T]`` (time last, as a torchrl
    ``Collector`` yields it); each env's steps after its last episode end wait for the next
    batch. ``state_dict`` / ``load_state_dict`` carry both the unfinished steps and the finished
    episodes through a checkpoint.
    """

    def __init__(self, capacity: int = 10) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}.")
        self.capacity = capacity
        self.episodes: deque[TensorDictBase] = deque(maxlen=capacity)
        self._open: list[TensorDictBase | None] = []

    def __len__(self) -> int:
        return len(self.episodes)

    def extend(self, batch: TensorDictBase) -> None:
        steps = batch.select(*EPISODE_KEYS)
        steps = steps.reshape(-1, steps.shape[-1])  # [envs, T]
        if not self._open:
            self._open = [None] * steps.shape[0]
        if len(self._open) != steps.shape[0]:
            raise ValueError(
                f"RecentEpisodes saw {len(self._open)} envs before and {steps.shape[0]} now."
            )
        done = steps.get(("next", "done")).reshape(steps.shape)
        for env, ends in enumerate(done):
            start = 0
            for end in ends.nonzero().flatten().tolist():
                self.episodes.append(self._join(env, steps[env, start : end + 1]))
                self._open[env] = None
                start = end + 1
            if start < steps.shape[1]:
                self._open[env] = self._join(env, steps[env, start:])

    def _join(self, env: int, part: TensorDictBase) -> TensorDictBase:
        carried = self._open[env]
        return part.clone() if carried is None else torch.cat([carried, part.clone()], 0)

    def state_dict(self) -> dict[str, Any]:
        return {
            "capacity": self.capacity,
            "episodes": [ep.to_dict() for ep in self.episodes],
            "open": [None if part is None else part.to_dict() for part in self._open],
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        def load(data: dict) -> TensorDictBase:
            return TensorDict(data, batch_size=[data["observation"].shape[0]])

        self.capacity = state["capacity"]
        self.episodes = deque((load(ep) for ep in state["episodes"]), maxlen=self.capacity)
        self._open = [None if part is None else load(part) for part in state["open"]]


def discounted_returns(signal: Tensor, gamma: float, terminated: bool) -> Tensor:
    """``G_t = sum_{k >= t} gamma^(k - t) s_k`` over one episode's ``signal`` ``[L]``.

    An episode ended by its time limit (``terminated=False``) goes on for a critic, which
    bootstraps there; its return then gets the tail ``gamma^(L - t) * s_bar / (1 - gamma)``,
    ``s_bar`` the mean signal of its last ``ceil(1 / (1 - gamma))`` steps (the signal's rate
    taken as steady after the limit, an approximation). Computed in float64.
    """
    values = signal.detach().to(torch.float64).reshape(-1).tolist()
    returns = [0.0] * len(values)
    running = 0.0
    if not terminated and gamma < 1.0:
        window = min(len(values), math.ceil(1.0 / (1.0 - gamma)))
        running = sum(values[-window:]) / window / (1.0 - gamma)
    for t in range(len(values) - 1, -1, -1):
        running = values[t] + gamma * running
        returns[t] = running
    return torch.tensor(returns, dtype=torch.float64)


@torch.no_grad()
def critic_calibration(
    loss,
    episodes: list[TensorDictBase],
    gamma: float,
    max_rows: int = 2000,
) -> dict[str, float]:
    """The critics at the steps of ``episodes`` against the steps' discounted returns.

    ``loss`` is a :class:`~s3rl_torchrl.objectives.SACLagLoss` (its current critics: the reward
    pair through its min, the cost pair as the actor loss reads it), both signals discounted
    with ``gamma``. Rows are every ``ceil(rows / max_rows)``-th step. Returns, for ``reward``
    and ``cost`` (summed over costs): ``critic/<signal>_q`` (mean prediction),
    ``critic/<signal>_return`` (mean return), ``critic/<signal>_error`` (mean prediction minus
    return) and ``critic/<signal>_rmse``; NaN without a finished episode. The reward critic is a
    soft critic: its value includes the entropy bonus, which its error therefore includes too.
    """
    names = ("q", "return", "error", "rmse")
    out = {f"critic/{s}_{n}": math.nan for s in ("reward", "cost") for n in names}
    if not episodes:
        return out
    rows, reward_returns, cost_returns = [], [], []
    for episode in episodes:
        terminated = bool(episode.get(("next", "terminated"))[-1].any())
        reward_returns.append(discounted_returns(episode.get(("next", "reward")), gamma, terminated))
        cost = episode.get(("next", "cost")).sum(-1)
        cost_returns.append(discounted_returns(cost, gamma, terminated))
        rows.append(episode.select("observation", "action"))
    data = torch.cat(rows, 0)
    targets = {"reward": torch.cat(reward_returns), "cost": torch.cat(cost_returns)}
    stride = max(1, math.ceil(data.shape[0] / max_rows))
    data = data[::stride]
    q_reward, q_cost = loss.critic_values(data)
    predictions = {"reward": q_reward.min(0)[0]}
    if q_cost is not None:
        read = loss.read_cost(q_cost)
        if loss.cost_nonnegative:
            read = read.clamp_min(0.0)
        predictions["cost"] = read.sum(0)
    for signal, prediction in predictions.items():
        target = targets[signal][::stride]
        prediction = prediction.reshape(-1).to(torch.float64)
        error = prediction - target
        out[f"critic/{signal}_q"] = float(prediction.mean())
        out[f"critic/{signal}_return"] = float(target.mean())
        out[f"critic/{signal}_error"] = float(error.mean())
        out[f"critic/{signal}_rmse"] = float(error.square().mean().sqrt())
    return out


def actor_gradient_norms(loss, batch: TensorDictBase) -> dict[str, float]:
    """Norm of the gradient of each actor-loss term with respect to the actor's parameters:
    ``grad/entropy`` (``alpha log pi``), ``grad/reward`` (``-Q_0``) and ``grad/cost``
    (``lambda Q_c``), as each enters the loss (``SACLagLoss.actor_loss_terms``; NaN for a term
    the loss does not have). Draws the actor's action from the global torch generator: call it
    under ``torch.random.fork_rng()`` to leave training's random stream as it was."""
    terms = loss.actor_loss_terms(batch)
    params = [p for p in loss.actor_network_params.values(True, True) if p.requires_grad]
    out = {f"grad/{name}": math.nan for name in ("entropy", "reward", "cost")}
    for name, term in terms.items():
        grads = torch.autograd.grad(term, params, retain_graph=True, allow_unused=True)
        squares = [g.detach().square().sum() for g in grads if g is not None]
        out[f"grad/{name}"] = float(torch.stack(squares).sum().sqrt()) if squares else 0.0
    return out
