"""s3rl-torchrl: safe (constrained) reinforcement learning for TorchRL.

Importing the package registers the velocity tasks with Gymnasium.
"""

from s3rl_torchrl import envs, transforms  # noqa: F401  (registers the tasks)

__version__ = "0.1.0"
