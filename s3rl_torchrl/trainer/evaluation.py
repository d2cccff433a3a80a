"""Deterministic evaluation: episode reward, cost and length statistics, safe-state occupancy."""

from __future__ import annotations

import json
import math
import statistics
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from copy import deepcopy
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp


@dataclass
class EvalResult:
    """Statistics over evaluation episodes (the keys of ``final_eval.json``).

    ``safe_occupancy`` is the percentage of evaluated steps whose cost is zero.
    Standard deviations are population std (``ddof=0``), as FSRL reports. The per-episode
    values (``episode_*``, in evaluation order) let ``s3rl-report`` pool episodes over seeds
    (Welch's t-test, Table 1 "over episodes"); files written before they existed lack them.
    """

    reward_mean: float
    reward_std: float
    cost_mean: float
    cost_std: float
    length_mean: float
    safe_occupancy: float
    episodes: int
    episode_rewards: list[float] = field(default_factory=list)
    episode_costs: list[float] = field(default_factory=list)
    episode_lengths: list[int] = field(default_factory=list)
    episode_safe_steps: list[int] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")


def episode_statistics(rollout: TensorDictBase) -> list[tuple[float, float, int, int]]:
    """Per env copy of a ``[num_envs, T]`` rollout that began at a reset: its first episode's
    (reward, cost, length, safe steps).

    The episode ends at the copy's first ``("next", "done")`` or, still running, at the
    rollout's last step (a ``max_steps`` shorter than the task's episode cuts it there). A
    copy's later episodes are not counted: one that began after a reset inside the rollout is
    whole only if it ends before the rollout does, so counting it would favour short episodes
    (a robot that falls early), and the remainder the rollout cuts is no episode. Sums are in
    float64, as the per-step rewards summed in Python before.
    """
    reward = rollout["next", "reward"].sum(-1).double()
    cost = rollout["next", "cost"].sum(-1).double()
    done = rollout["next", "done"].squeeze(-1).clone()
    done[..., -1] = True
    end = done.to(torch.uint8).argmax(-1, keepdim=True)  # each copy's first done step
    in_episode = torch.arange(done.shape[-1], device=done.device) <= end
    return list(
        zip(
            reward.where(in_episode, 0.0).sum(-1).reshape(-1).tolist(),
            cost.where(in_episode, 0.0).sum(-1).reshape(-1).tolist(),
            (end + 1).reshape(-1).tolist(),
            ((cost == 0) & in_episode).sum(-1).reshape(-1).tolist(),
        )
    )


def evaluate(
    env: EnvBase,
    policy: Callable[[TensorDictBase], TensorDictBase],
    episodes: int,
    max_steps: int = 1000,
) -> EvalResult:
    """Run ``policy`` deterministically on ``env`` until ``episodes`` episodes have ended.

    Rollouts of ``max_steps`` steps start from a reset; each copy of a batched env contributes
    its first episode (:func:`episode_statistics`), and the first ``episodes`` are kept.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}.")
    collected: list[tuple[float, float, int, int]] = []
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        while len(collected) < episodes:
            rollout = env.rollout(max_steps, policy, break_when_any_done=False)
            if rollout.ndim == 1:
                rollout = rollout.unsqueeze(0)
            collected.extend(episode_statistics(rollout))
    collected = collected[:episodes]
    rewards, costs, lengths, safe = (list(x) for x in zip(*collected))
    return EvalResult(
        reward_mean=statistics.fmean(rewards),
        reward_std=statistics.pstdev(rewards),
        cost_mean=statistics.fmean(costs),
        cost_std=statistics.pstdev(costs),
        length_mean=statistics.fmean(lengths),
        safe_occupancy=100.0 * sum(safe) / sum(lengths),
        episodes=len(collected),
        episode_rewards=rewards,
        episode_costs=costs,
        episode_lengths=lengths,
        episode_safe_steps=[int(n) for n in safe],
    )


@dataclass
class BestFeasible:
    """FSRL's choice of the checkpoint to keep (``fsrl/trainer/base_trainer.py``,
    ``perf_is_better``), applied to each epoch's deterministic evaluation: until an epoch is
    within the cost limit, an epoch that is within it or has a higher reward replaces the best;
    after that, only an epoch within the limit with a higher reward does. Its ``model_best.pt``
    read in a 10-episode evaluation may be how the paper's Table 1 was made."""

    reward: float = -math.inf
    cost: float = math.inf
    epoch: int = 0  # 0: no epoch evaluated yet
    frames: int = 0

    def update(self, reward: float, cost: float, limit: float, epoch: int, frames: int) -> bool:
        """True if this epoch's evaluation (``reward``, ``cost``) becomes the best."""
        if self.cost > limit:
            better = cost <= limit or reward > self.reward
        else:
            better = cost <= limit and reward > self.reward
        if better:
            self.reward, self.cost, self.epoch, self.frames = reward, cost, epoch, frames
        return better


class DeliveryCandidates:
    """The policies of the last ``epochs`` epochs (``eval.delivery_epochs``), from which a run
    picks the one it delivers after training (:func:`pick_delivered`).

    The multiplier holds the *training* policy's cost near its target; the deterministic
    policy of any one epoch can sit on either side of it, far above on some tasks, so the last
    epoch's is a draw. Picking among the last few epochs' policies on fresh episodes each, and
    reporting the pick on other episodes, delivers one that has shown its cost.
    """

    def __init__(self, epochs: int):
        if isinstance(epochs, bool) or not isinstance(epochs, int) or epochs < 1:
            raise ValueError(f"epochs must be an integer >= 1, got {epochs!r}.")
        self.epochs = epochs
        self.candidates: deque[dict[str, Any]] = deque(maxlen=epochs)

    def add(self, epoch: int, frames: int, policy: torch.nn.Module) -> None:
        """Keep a copy of ``policy``'s weights as this epoch's candidate."""
        weights = {k: v.detach().clone() for k, v in policy.state_dict().items()}
        self.candidates.append({"epoch": int(epoch), "frames": int(frames), "weights": weights})

    def policies(self, policy: torch.nn.Module) -> Iterator[tuple[dict[str, Any], torch.nn.Module]]:
        """Each candidate (oldest first) as a copy of ``policy`` holding its weights."""
        for candidate in self.candidates:
            copy = deepcopy(policy)
            copy.load_state_dict(candidate["weights"])
            yield candidate, copy

    def state_dict(self) -> dict[str, Any]:
        return {"epochs": self.epochs, "candidates": list(self.candidates)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.candidates = deque(state["candidates"], maxlen=self.epochs)


def pick_delivered(results: Sequence[EvalResult], cost_limit: float) -> tuple[int, bool]:
    """The index of the result to deliver and whether it is within ``cost_limit``: the highest
    mean reward among those whose mean cost is at most the limit (the later one on a tie), or,
    if none is, the lowest mean cost (the later one on a tie)."""
    if not results:
        raise ValueError("no candidate to pick from")
    feasible = [i for i, r in enumerate(results) if r.cost_mean <= cost_limit]
    if feasible:
        return max(feasible, key=lambda i: (results[i].reward_mean, i)), True
    return min(range(len(results)), key=lambda i: (results[i].cost_mean, -i)), False


# The paper's training budget ("1M steps", experiment=paper): shorter runs are not converged.
PAPER_FRAMES = 1_000_000


def constraint_verdict(cost: float, limit: float, frames: int) -> str:
    """One sentence under the result table: does the final evaluation keep the cost limit?"""
    if cost <= limit:
        return f"Within the cost limit: mean cost {cost:.2f} <= d = {limit:g}."
    verdict = f"Over the cost limit: mean cost {cost:.2f} > d = {limit:g} after {frames} frames"
    if frames < PAPER_FRAMES:
        return (
            f"{verdict}. A run this short has not converged: the paper trains "
            f"{PAPER_FRAMES // 1000}k frames (docs/results.md, \"What differs from the paper\")."
        )
    return f"{verdict}: this policy does not keep the constraint."


class RandomPolicy:
    """Uniform random actions from the env's action spec: the reference a trained policy beats."""

    def __init__(self, env: EnvBase):
        self.env = env

    def __call__(self, tensordict: TensorDictBase) -> TensorDictBase:
        return self.env.rand_action(tensordict)


def format_table(
    rows: dict[str, EvalResult],
    title: str = "Final evaluation",
    grad_steps: dict[str, int] | None = None,
) -> str:
    """A Markdown table of evaluation results, one row per label.

    ``grad_steps`` (label -> gradient steps the policy was trained with) adds a column, so a
    policy that never learned shows it; labels without an entry (a random baseline) get "-".
    """
    header = "| run | episodes | reward | cost | length | safe steps (%) |"
    rule = "|---|---:|---:|---:|---:|---:|"
    if grad_steps is not None:
        header += " gradient steps |"
        rule += "---:|"
    lines = [f"{title}", "", header, rule]
    for label, r in rows.items():
        line = (
            f"| {label} | {r.episodes} | {r.reward_mean:.2f} ± {r.reward_std:.2f} | "
            f"{r.cost_mean:.2f} ± {r.cost_std:.2f} | {r.length_mean:.1f} | "
            f"{r.safe_occupancy:.1f} |"
        )
        if grad_steps is not None:
            line += f" {grad_steps.get(label, '-')} |"
        lines.append(line)
    return "\n".join(lines)


def record_video(
    env: EnvBase, policy, path: str | Path, max_steps: int = 1000, fps: int | None = None
) -> Path:
    """Roll out one deterministic episode (at most ``max_steps`` steps) on a video env and
    write its frames as they come: the reset frame, then one frame per step.

    ``env`` is :func:`~s3rl_torchrl.envs.video.make_video_env`'s: its ``"pixels"`` carry the
    unsafe-step border and the running cost and reward (docs/video.md). The format follows
    the suffix (``.mp4``, ``.gif``; :class:`~s3rl_torchrl.envs.video.VideoWriter`).
    """
    from s3rl_torchrl.envs.video import VIDEO_FPS, VideoWriter

    path = Path(path)
    with (
        set_exploration_type(ExplorationType.DETERMINISTIC),
        torch.no_grad(),
        VideoWriter(path, fps or VIDEO_FPS) as writer,
    ):
        tensordict = env.reset()
        writer.append(tensordict["pixels"].cpu().numpy())
        for _ in range(max_steps):
            tensordict = env.step(policy(tensordict))
            writer.append(tensordict["next", "pixels"].cpu().numpy())
            if tensordict["next", "done"].any():
                break
            tensordict = step_mdp(tensordict)
    return path
