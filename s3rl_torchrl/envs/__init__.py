"""Safety-Gymnasium-style velocity tasks on Gymnasium's MuJoCo robots, as TorchRL envs."""

from s3rl_torchrl.envs.make import BATCHING_CHOICES, make_base_env, make_env
from s3rl_torchrl.envs.registry import (
    TASKS,
    VELOCITY_TASKS,
    RegisteredTask,
    VelocityTask,
    get_task,
    task_names,
)
from s3rl_torchrl.envs.velocity import register_velocity_tasks, velocity_cost

register_velocity_tasks()

__all__ = [
    "BATCHING_CHOICES",
    "TASKS",
    "VELOCITY_TASKS",
    "RegisteredTask",
    "VelocityTask",
    "get_task",
    "make_base_env",
    "make_env",
    "register_velocity_tasks",
    "task_names",
    "velocity_cost",
]
