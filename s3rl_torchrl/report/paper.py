"""The paper's reported numbers (Table 1, Table 2, Figure 3's quoted differences), as package data.

``data/paper_results.csv`` holds one value per row (task, method, metric, mean, std) with its
source in the file's header. Velocity tasks are named ``Safety<Robot>VelocityGymnasium-<v>`` in
the paper (Safety-Gymnasium's Gymnasium-API ids); :func:`paper_results_for` also finds them
under this package's id ``Safety<Robot>Velocity-<v>`` of the same task.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import cache
from importlib import resources

__all__ = ["PaperValue", "load_paper_results", "paper_results_for", "PAPER_TITLE"]

PAPER_TITLE = (
    "Safety Aware Constrained Reinforcement Learning via Contrastive State Representations"
)
DATA_FILE = "paper_results.csv"


@dataclass(frozen=True)
class PaperValue:
    table: str  # "Table 1", "Table 2" or "Figure 3" (differences quoted in Section 4.3)
    paper_label: str  # the task as printed
    task: str  # environment id
    setting: str  # "Lag" or "Non-Lag"
    method: str  # the paper's name, e.g. "SAC-LAG"
    algo: str  # this package's algo name ("" for a value shared by both methods)
    metric: str  # "reward", "cost", "length" or "safe_occupancy_diff_pp"
    mean: float
    std: float


@cache
def load_paper_results() -> tuple[PaperValue, ...]:
    """Every value of the data file, in file order."""
    text = resources.files("s3rl_torchrl.report").joinpath("data", DATA_FILE).read_text()
    rows = csv.DictReader(line for line in text.splitlines() if not line.startswith("#"))
    return tuple(
        PaperValue(**{**row, "mean": float(row["mean"]), "std": float(row["std"])})
        for row in rows
    )


def task_aliases(task: str) -> set[str]:
    """``task`` and every registered id of the same task (e.g. a velocity task's
    ``Safety<Robot>Velocity-<v>`` and ``Safety<Robot>VelocityGymnasium-<v>``)."""
    from s3rl_torchrl.envs.registry import TASKS

    spec = TASKS.get(task)
    if spec is None:
        return {task}
    main = spec.alias_of or task
    return {task, main} | {name for name, s in TASKS.items() if s.alias_of == main}


def paper_results_for(task: str) -> list[PaperValue]:
    """The paper's values for a task (by any of its ids); empty if the paper has none."""
    names = task_aliases(task)
    return [value for value in load_paper_results() if value.task in names]
