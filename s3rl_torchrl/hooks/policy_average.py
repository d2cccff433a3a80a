"""Exponential moving averages of the actor's weights, evaluated beside the policy itself
(``eval.ema_horizons``, off by default; docs/recipes.md, "The delivered policy").

The multiplier swings, and the deterministic policy of any one epoch swings with it: on several
tasks its cost goes from 0 to far over the limit within a few epochs while the mean over those
epochs sits below it (research/2026-12-04-delivery-rules.md). An average of the actor's weights
over the last ``h`` gradient steps (decay ``1 - 1/h`` per step: torch's
``get_ema_multi_avg_fn``, one ``torch._foreach_lerp_`` over the weights) may sit nearer that
mean than the last weights do. Each average is evaluated deterministically at every epoch's end (``ema<h>/reward``,
``ema<h>/cost``, ``ema<h>/length`` in the epoch's row) and after training on the final episodes
(``final_eval.json``'s ``ema<h>``).

The averages are evaluated on test envs of their own (the run's test seed + ``SEED_OFFSET``),
so the run's own evaluations, and everything trained, are the same with and without them. The
averages and those envs' state are the hook's state, in the checkpoint.
"""

from __future__ import annotations

from copy import deepcopy
from typing import Any

import torch
from torchrl.envs import EnvBase

from s3rl_torchrl.envs import make_env
from s3rl_torchrl.envs.state import env_snapshot, restore_env
from s3rl_torchrl.hooks.base import HookHost, TrainerHook

__all__ = ["PolicyAverage", "ema_name"]

#: Added to the run's test seed for the averages' test envs: apart from the run's own test envs
#: (seed + 100_000) and from the training envs (seed).
SEED_OFFSET = 200_000


class WeightAverage:
    """An exponential moving average of ``module``'s weights with ``decay`` per update: the
    first update copies them, each later one moves ``1 - decay`` of the way to them (buffers are
    copied). ``torch.optim.swa_utils.AveragedModel`` computes the same average with the same
    ``_foreach_lerp_`` (``tests/hooks/test_policy_average.py`` holds the two together), but
    listing the actor's tensors and its bookkeeping at every update took 12x as long: two
    averages of the preset's S3RL actor, 470 against 39 us a gradient step of ~4.7 ms
    (``research/studies/weight_average_cost.py``)."""

    def __init__(self, module: torch.nn.Module, decay: float) -> None:
        self.module = deepcopy(module).requires_grad_(False)
        self.weight = 1.0 - decay
        self.updates = 0
        self._averaged = list(self.module.parameters()) + list(self.module.buffers())
        # The source's tensors, listed once per source module: walking a TensorDictModule's
        # tree for them costs more than the average itself (the optimiser updates them in
        # place, so the list stays valid).
        self._source: tuple[torch.nn.Module, list[torch.Tensor], int] | None = None

    def _tensors(self, source: torch.nn.Module) -> tuple[list[torch.Tensor], int]:
        if self._source is None or self._source[0] is not source:
            params = [p.detach() for p in source.parameters()]
            self._source = (source, params + list(source.buffers()), len(params))
        return self._source[1], self._source[2]

    @torch.no_grad()
    def update(self, source: torch.nn.Module) -> None:
        current, n_params = self._tensors(source)
        if len(current) != len(self._averaged):
            raise ValueError("the source module's weights do not match the averaged module's")
        if self.updates == 0:
            torch._foreach_copy_(self._averaged, current)
        else:
            torch._foreach_lerp_(self._averaged[:n_params], current[:n_params], self.weight)
            if len(current) > n_params:  # buffers are copied, not averaged
                torch._foreach_copy_(self._averaged[n_params:], current[n_params:])
        self.updates += 1

    def state_dict(self) -> dict[str, Any]:
        return {"module": self.module.state_dict(), "updates": self.updates}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if "n_averaged" in state:  # an AveragedModel's, as the hook kept it before WeightAverage
            weights = {k.removeprefix("module."): v for k, v in state.items() if k != "n_averaged"}
            self.module.load_state_dict(weights)
            self.updates = int(state["n_averaged"])
            return
        self.module.load_state_dict(state["module"])
        self.updates = int(state["updates"])


def ema_name(horizon: int) -> str:
    """The name of the average over about ``horizon`` gradient steps: its columns' prefix and
    its key in ``final_eval.json``."""
    return f"ema{horizon}"


class PolicyAverage(TrainerHook):
    """One exponential moving average of ``actor``'s weights per horizon ``h`` in ``horizons``
    (decay ``1 - 1/h`` per gradient step), each evaluated on ``episodes`` deterministic episodes
    of ``task`` at every epoch's end.

    ``evaluate(env, policy, episodes, max_steps) -> EvalResult`` is the trainer's evaluation;
    the test envs are built on first use (``make_env``: ``num_envs`` copies seeded with
    ``seed``, ``env_kwargs``).
    """

    def __init__(
        self,
        actor: torch.nn.Module,
        horizons: list[int],
        task: str,
        seed: int,
        num_envs: int,
        episodes: int,
        max_steps: int | None,
        evaluate,
        **env_kwargs: Any,
    ) -> None:
        if not horizons or any(h < 1 for h in horizons) or len(set(horizons)) != len(horizons):
            raise ValueError(f"horizons must be distinct integers >= 1, got {horizons!r}.")
        self.actor, self.horizons = actor, list(horizons)
        self.averages = {h: WeightAverage(actor, 1.0 - 1.0 / h) for h in self.horizons}
        self.task, self.seed, self.num_envs = task, seed, num_envs
        self.episodes, self.max_steps, self._evaluate = episodes, max_steps, evaluate
        self.env_kwargs = env_kwargs  # make_env's device, batching
        self._env: EnvBase | None = None
        self._env_state: dict[str, Any] | None = None  # a resumed run's, until the env is built

    @classmethod
    def for_run(cls, cfg, actor: torch.nn.Module, evaluate) -> PolicyAverage:
        """The run ``cfg``'s hook on ``actor``: ``eval.ema_horizons``, its task, seed and
        evaluation settings."""
        from s3rl_torchrl.trainer.evaluate_checkpoint import TEST_SEED_OFFSET

        return cls(
            actor,
            list(cfg.eval.ema_horizons),
            cfg.task.name,
            cfg.seed + TEST_SEED_OFFSET + SEED_OFFSET,
            cfg.eval.num_envs,
            cfg.eval.episodes,
            cfg.eval.max_steps,
            evaluate,
            device=cfg.device,
            batching=cfg.collector.batching,
        )

    def register(self, host: HookHost, name: str) -> None:
        host.register_op("after_update", self.update)
        host.register_op("after_evaluation", self.measure)
        host.register_op("final_evaluation", self.final)
        host.register_module(name, self)

    def policy(self, horizon: int) -> torch.nn.Module:
        """The average over ``horizon`` steps, as a module like the actor."""
        return self.averages[horizon].module

    def update(self, losses) -> None:
        for average in self.averages.values():
            average.update(self.actor)

    @property
    def env(self) -> EnvBase:
        if self._env is None:
            self._env = make_env(
                self.task, num_envs=self.num_envs, seed=self.seed, **self.env_kwargs
            )
            if self._env_state is not None:
                restore_env(self._env, self._env_state)
                self._env_state = None
        return self._env

    def _results(self, episodes: int, max_steps: int | None) -> dict[str, Any]:
        return {
            ema_name(h): self._evaluate(self.env, self.policy(h), episodes, max_steps)
            for h in self.horizons
        }

    def measure(self, row: dict[str, Any]) -> dict[str, float]:
        """``after_evaluation`` op: each average's evaluation, as columns of the epoch's row."""
        out = {}
        for name, result in self._results(self.episodes, self.max_steps).items():
            out[f"{name}/reward"] = result.reward_mean
            out[f"{name}/cost"] = result.cost_mean
            out[f"{name}/length"] = result.length_mean
        return out

    def final(self, episodes: int, max_steps: int | None) -> dict[str, Any]:
        """``final_evaluation`` op: each average on the final episodes, by name."""
        return self._results(episodes, max_steps)

    def state_dict(self) -> dict[str, Any]:
        env_state = env_snapshot(self._env) if self._env is not None else self._env_state
        return {
            "averages": {h: average.state_dict() for h, average in self.averages.items()},
            "env": env_state,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if not state:
            return
        for h, average in self.averages.items():
            average.load_state_dict(state["averages"][h])
        if state.get("env") is not None:
            if self._env is not None:
                restore_env(self._env, state["env"])
            else:
                self._env_state = state["env"]
