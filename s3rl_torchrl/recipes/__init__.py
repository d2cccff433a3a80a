"""The Hydra recipes behind the console scripts ``s3rl-train`` and ``s3rl-eval``.

Their configs are the YAML files of the repository's top-level ``configs/``: a wheel ships that
directory inside the package as ``s3rl_torchrl/configs/`` (``pyproject.toml`` maps it), a source
checkout (editable install) reads it in place. :func:`config_dir` finds whichever is there.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

CONFIG_NAMES = ("train.yaml", "evaluate.yaml")


def config_dir() -> Path:
    """The directory holding ``train.yaml`` and ``evaluate.yaml`` and the config groups."""
    package = Path(__file__).resolve().parents[1]
    candidates = (package / "configs", package.parent / "configs")  # wheel, source checkout
    for candidate in candidates:
        if all((candidate / name).is_file() for name in CONFIG_NAMES):
            return candidate
    raise FileNotFoundError(
        "The s3rl-torchrl configs are missing: looked for "
        + " and ".join(str(c) for c in candidates)
        + ". Reinstall the package (pip install s3rl-torchrl, or pip install -e . in a checkout)."
    )


# Warnings of third-party code that a user of the recipes cannot act on, each matched exactly
# (never all warnings). Their causes are not ours: tensordict reads a torch._dynamo option that
# torch deprecated; Gymnasium's half_cheetah.xml (HalfCheetah-v4, the velocity task's robot)
# uses MuJoCo's deprecated settotalmass attribute.
TENSORDICT_DYNAMO_OPTION = r"torch\._dynamo\.config\.inline_inbuilt_nn_modules is deprecated"
MUJOCO_SETTOTALMASS = "compiler attribute 'settotalmass' is deprecated"


def quiet_known_warnings() -> None:
    """Silence exactly the third-party warnings above; every other warning is shown as before
    (MuJoCo's on stderr, with its ``WARNING:`` prefix)."""
    import mujoco

    warnings.filterwarnings(
        "ignore", message=TENSORDICT_DYNAMO_OPTION, category=FutureWarning, module="tensordict"
    )
    previous = mujoco.get_mju_user_warning()

    def on_mujoco_warning(message: str) -> None:
        if message.startswith(MUJOCO_SETTOTALMASS):
            return
        if previous is not None:
            previous(message)
        else:
            print(f"WARNING: {message}", file=sys.stderr)

    mujoco.set_mju_user_warning(on_mujoco_warning)
