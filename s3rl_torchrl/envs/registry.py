"""The velocity-task registry: one entry per Safety-Gymnasium task, everything else derived.

Thresholds and the velocity each cost reads are Safety-Gymnasium 1.0's
(``safety_gymnasium/tasks/safe_velocity``), see ``shared/notes/reference-semantics.md`` §1.
Adding a task is one :class:`VelocityTask` entry in :data:`VELOCITY_TASKS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

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
        obs_dim: observation size of the Gymnasium v4 env (documentation and tests).
        terminates: whether the robot can fall and end an episode early.
    """

    robot: str
    version: str
    threshold: float
    speed: SpeedKind
    obs_dim: int
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
    VelocityTask("Ant", "v0", 2.5745, "xy", 27, terminates=True),
    VelocityTask("Ant", "v1", 2.6222, "xy", 27, terminates=True),
    VelocityTask("HalfCheetah", "v0", 2.8795, "x", 17, terminates=False),
    VelocityTask("HalfCheetah", "v1", 3.2096, "x", 17, terminates=False),
    VelocityTask("Hopper", "v0", 0.37315, "x", 11, terminates=True),
    VelocityTask("Hopper", "v1", 0.7402, "x", 11, terminates=True),
    VelocityTask("Humanoid", "v0", 2.3475, "xy", 376, terminates=True),
    VelocityTask("Humanoid", "v1", 1.4149, "xy", 376, terminates=True),
    VelocityTask("Swimmer", "v0", 0.04845, "xy", 8, terminates=False),
    VelocityTask("Swimmer", "v1", 0.2282, "x", 8, terminates=False),
    VelocityTask("Walker2d", "v0", 1.7075, "x", 17, terminates=True),
    VelocityTask("Walker2d", "v1", 2.3415, "x", 17, terminates=True),
)

MAX_EPISODE_STEPS = 1000


@dataclass(frozen=True)
class RegisteredTask:
    """One Gymnasium id of a velocity task and the robot version it runs on."""

    env_id: str
    task: VelocityTask
    mujoco_version: MujocoVersion


def _registered_tasks() -> dict[str, RegisteredTask]:
    out: dict[str, RegisteredTask] = {}
    for task in VELOCITY_TASKS:
        out[task.env_id] = RegisteredTask(task.env_id, task, "v4")
        out[task.gymnasium_api_id] = RegisteredTask(task.gymnasium_api_id, task, "v4")
        out[task.v5_env_id] = RegisteredTask(task.v5_env_id, task, "v5")
    return out


#: Every Gymnasium id this package registers, mapped to its task.
TASKS: dict[str, RegisteredTask] = _registered_tasks()


def task_names(include_v5: bool = True) -> list[str]:
    """Every registered task id, sorted (the valid values of ``make_env(task=...)``)."""
    return sorted(
        name for name, reg in TASKS.items() if include_v5 or reg.mujoco_version == "v4"
    )


def get_task(name: str) -> RegisteredTask:
    """Look a task id up, with an error that lists the valid ids."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(
            f"Unknown velocity task {name!r}. Valid tasks are: {', '.join(task_names())}."
        ) from None
