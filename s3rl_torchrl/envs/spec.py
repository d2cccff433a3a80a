"""What every task of the registry says about itself, whatever its family.

This module imports nothing from the rest of :mod:`s3rl_torchrl.envs`, so every family's
module (``velocity``, ``bullet``, ``circle``, ``goal``) can build its entries without import cycles.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The task families; each has its own module and Gymnasium registration.
FAMILIES: tuple[str, ...] = ("velocity", "bullet", "circle", "goal")

#: How to install each optional extra a task may need (named in the missing-package error).
EXTRA_INSTALL: dict[str, str] = {
    "bullet": (
        'pip install "s3rl-torchrl[bullet]" && pip install --no-deps bullet-safety-gym==1.4.0'
        " (`make setup` does both; see docs/installation.md)"
    ),
}


@dataclass(frozen=True)
class TaskSpec:
    """One task id of the registry: the facts the trainer, the docs and the tests read. What a
    preset tunes for a task is the preset's, not the task's (``experiment=safe``'s own values
    for some tasks: ``s3rl_torchrl/trainer/presets.py``).

    Attributes:
        env_id: the Gymnasium id, e.g. ``"SafetyBallRun-v0"`` (also the ``task=`` value).
        family: ``"velocity"``, ``"bullet"``, ``"circle"`` or ``"goal"``.
        source: where the task comes from, e.g. ``"bullet-safety-gym 1.4.0"``.
        max_episode_steps: the time limit (Gymnasium's ``TimeLimit``) of one episode.
        cost_limit: the default per-episode cost limit ``d`` (``task.cost_limit``): the paper's.
        obs_dim: observation size.
        act_dim: action size.
        cost_rule: the per-step cost in one line, e.g. ``"1 if vx > 3.2096"``.
        margin_rule: the graded safety margin the task writes to ``info["cost_margin"]`` (read
            by ``make_env(..., margin=True)`` into ``("next", "margin")``; negative exactly
            when the step costs), e.g. ``"3.2096 - vx"``; ``None`` if the task exposes none.
        extra: the pip extra the task needs (e.g. ``"bullet"``), ``None`` if always available.
        registered_as: the Gymnasium id this package registers for the task when it differs
            from ``env_id`` (the Bullet tasks: ``"s3rl_torchrl/SafetyBallRun-v0"``, because the
            upstream package registers ``"SafetyBallRun-v0"`` itself); ``None``: ``env_id``.
        requires_module: an optional module the task needs (e.g. ``"bullet_safety_gym"``),
            imported before the env is built so that a missing one fails naming ``extra``.
        alias_of: for a second id of the same task (e.g. the paper's ``...Gymnasium-v0`` ids),
            the main id; ``None`` for a main id.
        variant_of: for an opt-in variant that is a *different* task (e.g. a velocity task on
            Gymnasium's v5 robot), the id of the task it varies; ``None`` otherwise.
    """

    env_id: str
    family: str
    source: str
    max_episode_steps: int
    cost_limit: float
    obs_dim: int
    act_dim: int
    cost_rule: str
    margin_rule: str | None = None
    extra: str | None = None
    registered_as: str | None = None
    requires_module: str | None = None
    alias_of: str | None = None
    variant_of: str | None = None

    def __post_init__(self):
        if self.family not in FAMILIES:
            raise ValueError(
                f"TaskSpec({self.env_id!r}).family is {self.family!r}; "
                f"valid families are {', '.join(FAMILIES)}."
            )

    @property
    def gym_id(self) -> str:
        """What ``make_env`` passes to ``gymnasium.make``: ``"s3rl_torchrl:<registered id>"``.

        The module prefix makes Gymnasium import this package (which registers every id) first,
        which worker processes (torchrl's ParallelEnv, Gymnasium's AsyncVectorEnv) need.
        """
        return f"s3rl_torchrl:{self.registered_as or self.env_id}"
