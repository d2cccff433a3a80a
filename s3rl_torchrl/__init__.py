"""s3rl-torchrl: safe (constrained) reinforcement learning for TorchRL.

Importing the package registers the velocity tasks with Gymnasium, and gives tensordict's
``from_any`` a fast path for plain tensors (``_tensordict_fast_path``: 33 us less per
``TensorDictModule`` output). On a machine without a display it first picks MuJoCo's offscreen
OpenGL backend (``_render_backend``), which must happen before ``mujoco`` is imported.
"""

from s3rl_torchrl import _render_backend

_render_backend.select_mujoco_gl()

from s3rl_torchrl import _tensordict_fast_path  # noqa: E402

_tensordict_fast_path.install()

from s3rl_torchrl import envs, transforms  # noqa: E402,F401  (registers the tasks)

__version__ = "0.1.0"
