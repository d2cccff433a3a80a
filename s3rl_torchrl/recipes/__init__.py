"""The Hydra recipes behind the console scripts ``s3rl-train`` and ``s3rl-eval``.

Their configs are the YAML files of the repository's top-level ``configs/``: a wheel ships that
directory inside the package as ``s3rl_torchrl/configs/`` (``pyproject.toml`` maps it), a source
checkout (editable install) reads it in place. :func:`config_dir` finds whichever is there.
"""

from __future__ import annotations

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
