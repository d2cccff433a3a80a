"""A JSON record of an analysis (``s3rl-report lagrangian``, ``s3rl-report compare-runs``): its
result with the command that made it and the machine, as the benchmark scripts write theirs.

A record whose command and result are already in ``path`` is left as it is: rebuilding the
committed reports on another machine changes no file whose numbers did not change."""

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
    if _numbers(record) == _numbers(_read(path)):
        print(f"unchanged {path}")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2) + "\n")
    print(f"wrote {path}")


def _read(path: Path) -> dict | None:
    """The record already at ``path``, None where there is none (or it is not a JSON object)."""
    try:
        written = json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return written if isinstance(written, dict) else None


def _numbers(record: dict | None) -> dict | None:
    """A record without its machine, through JSON so tuples and int keys compare as written."""
    if record is None:
        return None
    return json.loads(json.dumps({k: v for k, v in record.items() if k != "machine"}))
