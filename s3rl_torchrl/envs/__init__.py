"""The tasks as TorchRL envs: Safety-Gymnasium velocity tasks, Bullet-Safety-Gym Run/Circle tasks,
Safety-Gymnasium Circle tasks and SafetyPointGoal1, all through one registry and :func:`make_env`."""

from s3rl_torchrl.envs.bullet import BULLET_TASKS, register_bullet_tasks
from s3rl_torchrl.envs.circle import CIRCLE_TASKS, register_circle_tasks
from s3rl_torchrl.envs.goal import GOAL_TASKS, register_goal_tasks
from s3rl_torchrl.envs.make import BATCHING_CHOICES, make_base_env, make_env, require_task_module
from s3rl_torchrl.envs.registry import (
    TASKS,
    VELOCITY_REGISTRATIONS,
    VELOCITY_SPECS,
    VELOCITY_TASKS,
    RegisteredTask,
    VelocityTask,
    get_task,
    task_names,
)
from s3rl_torchrl.envs.spec import TaskSpec
from s3rl_torchrl.envs.state import env_snapshot, exact_restore_unsupported, restore_env
from s3rl_torchrl.envs.velocity import register_velocity_tasks, velocity_cost

# Gymnasium registration, one call per family (none imports an optional package).
register_velocity_tasks()
register_bullet_tasks()
register_circle_tasks()
register_goal_tasks()

__all__ = [
    "BATCHING_CHOICES",
    "BULLET_TASKS",
    "CIRCLE_TASKS",
    "GOAL_TASKS",
    "TASKS",
    "VELOCITY_REGISTRATIONS",
    "VELOCITY_SPECS",
    "VELOCITY_TASKS",
    "RegisteredTask",
    "TaskSpec",
    "env_snapshot",
    "exact_restore_unsupported",
    "restore_env",
    "VelocityTask",
    "get_task",
    "make_base_env",
    "make_env",
    "register_bullet_tasks",
    "register_circle_tasks",
    "register_goal_tasks",
    "register_velocity_tasks",
    "require_task_module",
    "task_names",
    "velocity_cost",
]
