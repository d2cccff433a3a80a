"""s3rl-torchrl: safe (constrained) reinforcement learning for TorchRL.

Importing the package registers the velocity tasks with Gymnasium, and gives tensordict's
``from_any`` a fast path for plain tensors (``_tensordict_fast_path``: 33 us less per
``TensorDictModule`` output).
"""

from s3rl_torchrl import _tensordict_fast_path

_tensordict_fast_path.install()

from s3rl_torchrl import envs, transforms  # noqa: E402,F401  (registers the tasks)

__version__ = "0.1.0"
