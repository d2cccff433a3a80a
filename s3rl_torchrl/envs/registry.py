"""The task registry: one :class:`~s3rl_torchrl.envs.spec.TaskSpec` per Gymnasium id.

Every public lookup (:func:`get_task`, :func:`task_names`, the trainer's ``task=`` options,
:func:`~s3rl_torchrl.envs.make_env`) reads :data:`TASKS`, which collects the per-family tuples:

- velocity: Safety-Gymnasium 1.0's velocity tasks rebuilt on Gymnasium's MuJoCo robots
  (:data:`VELOCITY_TASKS` below; thresholds and the velocity each cost reads are those of
  Safety-Gymnasium's ``safety_gymnasium/tasks/safe_velocity`` code, documented at
  https://safety-gymnasium.readthedocs.io/en/latest/environments/safe_velocity.html);
- bullet: the Run and Circle tasks of the upstream ``bullet-safety-gym`` package
  (:data:`~s3rl_torchrl.envs.bullet.BULLET_TASKS`);
- circle: Safety-Gymnasium's Circle tasks rebuilt natively (``s3rl_torchrl.envs.circle``);
- goal: Safety-Gymnasium's SafetyPointGoal1 rebuilt natively (``s3rl_torchrl.envs.goal``).

Adding a task is one entry in its family's tuple.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from s3rl_torchrl.envs.bullet import BULLET_TASKS
from s3rl_torchrl.envs.circle import CIRCLE_TASKS
from s3rl_torchrl.envs.goal import GOAL_TASKS
from s3rl_torchrl.envs.spec import TaskSpec

# Each family's module defines its TaskSpec tuple (and registers its ids with Gymnasium in
# s3rl_torchrl/envs/__init__.py); a new family adds its import here and its tuple in TASKS.

SpeedKind = Literal["x", "xy"]
MujocoVersion = Literal["v4", "v5"]


@dataclass(frozen=True)
class VelocityTask:
    """A Safety-Gymnasium velocity task: a Gymnasium MuJoCo robot plus a speed limit.

    Attributes:
        robot: Gymnasium's MuJoCo robot name (``"HalfCheetah"`` -> ``HalfCheetah-v4``).
        version: the Safety-Gymnasium task version (``"v0"`` or ``"v1"``).
        threshold: the speed above which a step costs 1 (strict ``>``).
        speed: ``"x"`` for the signed forward velocity (running backwards never costs),
            ``"xy"`` for the planar speed ``sqrt(vx**2 + vy**2)``.
        obs_dim: observation size of the Gymnasium v4 env.
        act_dim: action size.
        v5_obs_dim: observation size of the Gymnasium v5 env (the ``...MujocoV5`` variant).
        terminates: whether the robot can fall and end an episode early.
    """

    robot: str
    version: str
    threshold: float
    speed: SpeedKind
    obs_dim: int
    act_dim: int
    v5_obs_dim: int
    terminates: bool

    @property
    def env_id(self) -> str:
        """The Safety-Gymnasium id, e.g. ``SafetyHalfCheetahVelocity-v1``."""
        return f"Safety{self.robot}Velocity-{self.version}"

    @property
    def gymnasium_api_id(self) -> str:
        """The id of Safety-Gymnasium's Gymnasium-API variant, which the paper and FSRL use."""
        return f"Safety{self.robot}VelocityGymnasium-{self.version}"

    @property
    def v5_env_id(self) -> str:
        """Opt-in variant on Gymnasium's v5 robot: a *different task* (thresholds are v4's)."""
        return f"Safety{self.robot}VelocityMujocoV5-{self.version}"

    def base_env_id(self, mujoco_version: MujocoVersion = "v4") -> str:
        return f"{self.robot}-{mujoco_version}"


VELOCITY_TASKS: tuple[VelocityTask, ...] = (
    VelocityTask("Ant", "v0", 2.5745, "xy", 27, 8, 105, terminates=True),
    VelocityTask("Ant", "v1", 2.6222, "xy", 27, 8, 105, terminates=True),
    VelocityTask("HalfCheetah", "v0", 2.8795, "x", 17, 6, 17, terminates=False),
    VelocityTask("HalfCheetah", "v1", 3.2096, "x", 17, 6, 17, terminates=False),
    VelocityTask("Hopper", "v0", 0.37315, "x", 11, 3, 11, terminates=True),
    VelocityTask("Hopper", "v1", 0.7402, "x", 11, 3, 11, terminates=True),
    VelocityTask("Humanoid", "v0", 2.3475, "xy", 376, 17, 348, terminates=True),
    VelocityTask("Humanoid", "v1", 1.4149, "xy", 376, 17, 348, terminates=True),
    VelocityTask("Swimmer", "v0", 0.04845, "xy", 8, 2, 8, terminates=False),
    VelocityTask("Swimmer", "v1", 0.2282, "x", 8, 2, 8, terminates=False),
    VelocityTask("Walker2d", "v0", 1.7075, "x", 17, 6, 17, terminates=True),
    VelocityTask("Walker2d", "v1", 2.3415, "x", 17, 6, 17, terminates=True),
)

MAX_EPISODE_STEPS = 1000
#: Default per-episode cost limit of every task: the paper's Table 3 (``cost_limit`` = 10).
PAPER_COST_LIMIT = 10.0


@dataclass(frozen=True)
class RegisteredTask:
    """One Gymnasium id of a velocity task and the robot version it runs on."""

    env_id: str
    task: VelocityTask
    mujoco_version: MujocoVersion


def _velocity_registrations() -> dict[str, RegisteredTask]:
    out: dict[str, RegisteredTask] = {}
    for task in VELOCITY_TASKS:
        out[task.env_id] = RegisteredTask(task.env_id, task, "v4")
        out[task.gymnasium_api_id] = RegisteredTask(task.gymnasium_api_id, task, "v4")
        out[task.v5_env_id] = RegisteredTask(task.v5_env_id, task, "v5")
    return out


#: Every velocity id mapped to its task and robot version (what velocity.py registers).
VELOCITY_REGISTRATIONS: dict[str, RegisteredTask] = _velocity_registrations()


def _velocity_spec(registered: RegisteredTask) -> TaskSpec:
    task, v5 = registered.task, registered.mujoco_version == "v5"
    velocity = "vx" if task.speed == "x" else "sqrt(vx^2 + vy^2)"
    robot = task.base_env_id(registered.mujoco_version)
    return TaskSpec(
        env_id=registered.env_id,
        family="velocity",
        source=f"Safety-Gymnasium 1.0 (native rebuild on Gymnasium {robot})",
        max_episode_steps=MAX_EPISODE_STEPS,
        cost_limit=PAPER_COST_LIMIT,
        obs_dim=task.v5_obs_dim if v5 else task.obs_dim,
        act_dim=task.act_dim,
        cost_rule=f"1 if {velocity} > {task.threshold}",
        margin_rule=f"{task.threshold} - {velocity}",
        alias_of=task.env_id if registered.env_id == task.gymnasium_api_id else None,
        variant_of=task.env_id if v5 else None,
    )


VELOCITY_SPECS: tuple[TaskSpec, ...] = tuple(
    _velocity_spec(r) for r in VELOCITY_REGISTRATIONS.values()
)


def _collect(*families: Iterable[TaskSpec]) -> dict[str, TaskSpec]:
    out: dict[str, TaskSpec] = {}
    for family in families:
        for spec in family:
            if spec.env_id in out:
                raise ValueError(f"Task id {spec.env_id!r} is defined twice in the registry.")
            out[spec.env_id] = spec
    return out


#: Every task id this package knows, mapped to its spec.
TASKS: dict[str, TaskSpec] = _collect(VELOCITY_SPECS, BULLET_TASKS, CIRCLE_TASKS, GOAL_TASKS)


def task_names(
    include_variants: bool = True, include_aliases: bool = True, family: str | None = None
) -> list[str]:
    """Registered task ids, sorted (the valid values of ``make_env(task=...)``).

    Args:
        include_variants: keep opt-in variants that are different tasks (the v5-robot ids).
        include_aliases: keep second ids of the same task (e.g. ``...VelocityGymnasium-v1``).
        family: only this family (``"velocity"``, ``"bullet"``, ``"circle"``, ``"goal"``).
    """
    return sorted(
        name
        for name, spec in TASKS.items()
        if (include_variants or spec.variant_of is None)
        and (include_aliases or spec.alias_of is None)
        and (family is None or spec.family == family)
    )


def get_task(name: str) -> TaskSpec:
    """Look a task id up, with an error that lists the valid ids."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(
            f"Unknown task {name!r}. Valid tasks are: {', '.join(task_names())}."
        ) from None


#: The task ids the S3RL paper evaluates (Table 1; ``SafetyDroneCircle-v0`` is in §4's text and
#: Figure 2).
PAPER_TASK_IDS: tuple[str, ...] = (
    "SafetyHalfCheetahVelocityGymnasium-v1",
    "SafetyHopperVelocityGymnasium-v1",
    "SafetySwimmerVelocityGymnasium-v1",
    "SafetyWalker2dVelocityGymnasium-v1",
    "SafetyAntVelocityGymnasium-v1",
    "SafetyHumanoidVelocityGymnasium-v1",
    "SafetyBallRun-v0",
    "SafetyCarRun-v0",
    "SafetyDroneRun-v0",
    "SafetyAntRun-v0",
    "SafetyBallCircle-v0",
    "SafetyCarCircle-v0",
    "SafetyDroneCircle-v0",
    "SafetyAntCircle-v0",
    "SafetyPointCircle1Gymnasium-v0",
    "SafetyCarCircle1Gymnasium-v0",
    "SafetyPointGoal1Gymnasium-v0",
)


FAMILY_ORDER = {"velocity": 0, "bullet": 1, "circle": 2, "goal": 3}


def tasks_markdown_table() -> str:
    """The table of every task in ``docs/tasks.md`` (a test keeps the docs equal to it).

    One row per main id (aliases in the second column), paper tasks first, then the other
    tasks and the opt-in variants. Print it with ``python -c "from s3rl_torchrl.envs.registry
    import tasks_markdown_table; print(tasks_markdown_table())"``.
    """
    aliases: dict[str, list[str]] = {}
    for spec in TASKS.values():
        if spec.alias_of is not None:
            aliases.setdefault(spec.alias_of, []).append(spec.env_id)

    def paper_id(name: str) -> str | None:
        return next((i for i in (name, *aliases.get(name, ())) if i in PAPER_TASK_IDS), None)

    def order(spec: TaskSpec):
        in_paper = paper_id(spec.env_id) is not None
        return (not in_paper, spec.variant_of is not None, FAMILY_ORDER[spec.family], spec.env_id)

    lines = [
        "| task id | also registered as | paper | source | obs | act | episode length "
        "| cost per step | cost limit |",
        "|---|---|---|---|---:|---:|---:|---|---:|",
    ]
    for spec in sorted((s for s in TASKS.values() if s.alias_of is None), key=order):
        also = ", ".join(f"`{a}`" for a in sorted(aliases.get(spec.env_id, ())))
        paper = "yes" if paper_id(spec.env_id) else ""
        extra = f" (extra `{spec.extra}`)" if spec.extra else ""
        rule = spec.cost_rule.replace("|", "\\|")  # a bare | would split the table cell
        lines.append(
            f"| `{spec.env_id}` | {also} | {paper} | {spec.source}{extra} | {spec.obs_dim} "
            f"| {spec.act_dim} | {spec.max_episode_steps} | `{rule}` "
            f"| {spec.cost_limit:g} |"
        )
    return "\n".join(lines)
