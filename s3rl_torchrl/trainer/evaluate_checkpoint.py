"""Evaluate a saved policy: rebuild the run's actor from its checkpoint and roll it out.

By default the evaluation uses the run's own evaluation settings, read from the checkpoint's
config (:func:`eval_settings`), so that it measures what the run's final table measured.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from s3rl_torchrl.envs import get_task, make_env
from s3rl_torchrl.envs.video import make_video_env
from s3rl_torchrl.trainer.builders import build_agent, build_replay_buffer
from s3rl_torchrl.trainer.checkpoint import CheckpointError, load_checkpoint
from s3rl_torchrl.trainer.config import TrainConfig, saved_train_config
from s3rl_torchrl.trainer.evaluation import EvalResult, evaluate, record_video

# builders.build_envs seeds a run's test envs at its seed + this offset (apart from the
# training envs); tests/recipes/test_evaluate.py checks that both agree.
TEST_SEED_OFFSET = 100_000

# Where each default comes from in the run's config (for the printed summary).
RUN_SOURCES = {
    "episodes": "the run's eval.final_episodes",
    "num_envs": "the run's eval.num_envs",
    "seed": f"the run's test envs: its seed + {TEST_SEED_OFFSET}",
    "max_steps": "the run's eval.max_steps",
}


@dataclass
class EvalSettings:
    """What an evaluation of a checkpoint runs with, and where each value came from."""

    episodes: int
    num_envs: int
    seed: int
    max_steps: int
    # name -> "given", or the run's config entry it was read from (RUN_SOURCES)
    sources: dict[str, str] = field(default_factory=dict)

    def describe(self) -> str:
        """One line: ``episodes=2 (the run's eval.final_episodes), ...``."""
        return ", ".join(
            f"{name}={getattr(self, name)} ({self.sources.get(name, 'given')})"
            for name in RUN_SOURCES
        )

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in RUN_SOURCES} | {"sources": self.sources}


def eval_settings(
    cfg: TrainConfig,
    *,
    episodes: int | None = None,
    num_envs: int | None = None,
    seed: int | None = None,
    max_steps: int | None = None,
) -> EvalSettings:
    """The settings an evaluation of the run ``cfg`` uses: each argument given wins, each
    ``None`` is the run's own final evaluation's (``eval.final_episodes`` episodes on
    ``eval.num_envs`` test envs seeded as the run's, rollouts of ``eval.max_steps`` steps;
    the task's episode length if the run's config has none)."""
    run = {
        "episodes": cfg.eval.final_episodes,
        "num_envs": cfg.eval.num_envs,
        "seed": cfg.seed + TEST_SEED_OFFSET,
        "max_steps": cfg.eval.max_steps,
    }
    given = {"episodes": episodes, "num_envs": num_envs, "seed": seed, "max_steps": max_steps}
    values, sources = {}, {}
    for name, value in given.items():
        if value is not None:
            values[name], sources[name] = int(value), "given"
        else:
            values[name], sources[name] = run[name], RUN_SOURCES[name]
    if values["max_steps"] is None:  # a config saved without the validated episode length
        values["max_steps"] = get_task(cfg.task.name).max_episode_steps
        sources["max_steps"] = "the task's episode length"
    return EvalSettings(**values, sources=sources)


def load_policy(checkpoint: str | Path):
    """The trained actor of a checkpoint and the run's config (a :class:`TrainConfig`)."""
    state, _ = load_checkpoint(checkpoint)
    try:
        cfg = saved_train_config(state["config"])
    except Exception as err:
        raise CheckpointError(f"The checkpoint's config does not load: {err}") from err
    env = make_env(cfg.task.name, seed=0)
    agent = build_agent(cfg, env, build_replay_buffer(cfg.algo))
    try:
        agent.loss.load_state_dict(state["loss"])
    except RuntimeError as err:
        raise CheckpointError(f"The checkpoint's weights do not fit its own config: {err}") from err
    env.close()
    return agent.actor, cfg


def evaluate_policy(
    actor,
    cfg: TrainConfig,
    settings: EvalSettings,
    video_path: str | Path | None = None,
) -> EvalResult:
    """Deterministic evaluation of the run ``cfg``'s ``actor`` with ``settings`` on fresh test
    envs (built as the run's: same batching), and an optional video of one episode."""
    env = make_env(
        cfg.task.name,
        num_envs=settings.num_envs,
        seed=settings.seed,
        batching=cfg.collector.batching,
    )
    try:
        result = evaluate(env, actor, settings.episodes, settings.max_steps)
    finally:
        env.close()
    if video_path is not None:
        # A copy of the first test env (its seed), rendering; after the statistics, which it
        # does not change.
        video_env = make_video_env(cfg.task.name, seed=settings.seed)
        try:
            record_video(video_env, actor, video_path, settings.max_steps)
        finally:
            video_env.close()
    return result


def evaluate_checkpoint(
    checkpoint: str | Path,
    episodes: int | None = None,
    num_envs: int | None = None,
    seed: int | None = None,
    max_steps: int | None = None,
    video_path: str | Path | None = None,
) -> tuple[EvalResult, TrainConfig]:
    """Deterministic evaluation of a checkpoint on fresh test envs (and an optional video).

    Every setting left at ``None`` is the run's own (:func:`eval_settings`): a run trained with
    ``eval.max_steps=50`` is evaluated on 50-step rollouts unless ``max_steps`` says otherwise.
    """
    actor, cfg = load_policy(checkpoint)
    settings = eval_settings(
        cfg, episodes=episodes, num_envs=num_envs, seed=seed, max_steps=max_steps
    )
    return evaluate_policy(actor, cfg, settings, video_path), cfg
