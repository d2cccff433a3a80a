"""Other libraries' published results on this package's tasks (OmniSafe's off-policy benchmark,
FSRL's benchmark curves, DSRL's dataset), as package data beside the paper's numbers.

``data/peer_results.csv`` holds one row per (source, task, method) with the source, its
protocol and how each value was read (copied from a table or read off a plot) in the file's
header. They are other code at other settings (frames, cost limit, evaluation): the report
prints them beside ours for orientation, never as a test.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from functools import cache
from importlib import resources

from s3rl_torchrl.report.paper import task_aliases

__all__ = ["PeerValue", "load_peer_results", "peer_results_for"]

DATA_FILE = "peer_results.csv"


@dataclass(frozen=True)
class PeerValue:
    source: str  # "OmniSafe", "FSRL" or "DSRL"
    task: str  # environment id (this package's)
    method: str  # the source's name for it, e.g. "SACLag"
    frames: int  # environment steps the value is read at; 0: not a training run (DSRL)
    cost_limit: float  # nan: unconstrained
    reward: float
    reward_std: float  # nan where the source gives none
    cost: float  # nan where the source gives none (DSRL: within cost_limit by construction)
    cost_std: float
    approximate: bool  # read off a plot, not copied from a table


def _float(text: str) -> float:
    return float(text) if text.strip() else math.nan


@cache
def load_peer_results() -> tuple[PeerValue, ...]:
    """Every row of the data file, in file order."""
    text = resources.files("s3rl_torchrl.report").joinpath("data", DATA_FILE).read_text()
    rows = csv.DictReader(line for line in text.splitlines() if not line.startswith("#"))
    return tuple(
        PeerValue(
            source=row["source"],
            task=row["task"],
            method=row["method"],
            frames=int(row["frames"]),
            cost_limit=_float(row["cost_limit"]),
            reward=float(row["reward"]),
            reward_std=_float(row["reward_std"]),
            cost=_float(row["cost"]),
            cost_std=_float(row["cost_std"]),
            approximate=row["approximate"] == "1",
        )
        for row in rows
    )


def peer_results_for(task: str) -> list[PeerValue]:
    """The peers' values for a task (by any of its ids); empty if none has published one."""
    names = task_aliases(task)
    return [value for value in load_peer_results() if value.task in names]
