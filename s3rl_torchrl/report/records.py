"""A JSON record of an analysis (``s3rl-report lagrangian``, ``s3rl-report compare-runs``): its
result with the command that made it and the machine, as the benchmark scripts write theirs."""

from __future__ import annotations

import json
import platform
from pathlib import Path

__all__ = ["write_json"]


def write_json(path: str | Path, report: dict, command: str) -> None:
    """Write ``{"command": command, "machine": ..., **report}`` to ``path`` (indented JSON)."""
    import torch

    path = Path(path)
    machine = {"platform": platform.platform(), "torch": torch.__version__}
    record = {"command": command, "machine": machine, **report}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2) + "\n")
    print(f"wrote {path}")
