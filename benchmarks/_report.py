"""What every benchmark script writes: its results as JSON, with the command that made them."""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

import torch


def command_line() -> str:
    """The command as typed (``python benchmarks/<script>.py ...``)."""
    return "python " + " ".join(sys.argv)


def machine() -> dict[str, str]:
    return {"platform": platform.platform(), "torch": torch.__version__}


def write_report(path: Path, report: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {path}")
