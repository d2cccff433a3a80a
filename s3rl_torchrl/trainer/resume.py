"""The config a resumed run continues with: its own, plus the changes the user asks for.

``s3rl-train resume=<run dir>`` continues the run with the config its checkpoint was written
with; every other override on that command line is a *change* (``algo.lagrangian_lr=1e-4``,
``collector.total_frames=2000000`` to extend a run), printed and recorded in the run's
``config.json`` (``resumes``). What the saved weights, buffer and identity of the run depend on
cannot change (:data:`RESUME_LOCKED`): the task, the algorithm, the seed, the network sizes, the
buffer layout. Config groups (``task=...``, ``experiment=...``) cannot be given either: they
would replace many values at once.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from s3rl_torchrl.trainer.checkpoint import GROUP_FILE, CheckpointError, load_checkpoint
from s3rl_torchrl.trainer.config import TrainConfig, saved_config_node, to_container, validate

__all__ = ["RESUME_LOCKED", "resume_config", "saved_config"]

# Config fields a resume must not change: what the saved weights and buffer depend on, and what
# names the run (its seed: s3rl-report would count a relabelled run as another seed).
RESUME_LOCKED = [
    "task.name",
    "algo.name",
    "algo.lagrangian",
    "algo.lagrangian_cadence",
    "algo.lagrangian_eval_window",  # the Lagrangian's checkpointed windows
    "algo.contrastive",
    # What every stored step carries (a graded label, hooks/labels.py) and how the buffer is
    # partitioned: the buffer and the n-step transform's held frames were written with them.
    "algo.contrastive_cfg.label",
    "diagnostics.probes",
    "algo.buffer_size",
    "algo.n_step",
    "network.actor_hidden",
    "network.critic_hidden",
    "network.activation",
    "collector.num_envs",
    "collector.frames_per_batch",
    "collector.frames_per_epoch",
    "seed",
    "seeds",
]
# The config groups of s3rl-train (configs/<group>/): an override of one is not a single value.
CONFIG_GROUPS = (
    "task",
    "algo",
    "pid",
    "critic",
    "network",
    "collector",
    "eval",
    "logger",
    "experiment",
    "sweep",
)


def saved_config(run_dir: str | Path) -> dict[str, Any]:
    """The config a run's checkpoint was written with (a multi-seed group: the group's)."""
    run_dir = Path(run_dir).expanduser()
    group = run_dir / GROUP_FILE
    if group.is_file():
        return json.loads(group.read_text())
    state, _ = load_checkpoint(run_dir)
    return state["config"]


def _get(cfg: dict, dotted: str) -> Any:
    for part in dotted.split("."):
        if not isinstance(cfg, dict) or part not in cfg:
            return None
        cfg = cfg[part]
    return cfg


def config_changes(before: dict, after: dict, prefix: str = "") -> dict[str, tuple[Any, Any]]:
    """The leaves of two nested configs that differ, by dotted key: ``{key: (before, after)}``."""
    out = {}
    for key in sorted(set(before) | set(after)):
        a, b = before.get(key), after.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out.update(config_changes(a, b, f"{prefix}{key}."))
        elif a != b:
            out[f"{prefix}{key}"] = (a, b)
    return out


def resume_config(
    run_dir: str | Path, overrides: list[str] | tuple[str, ...] = (), *, echo: bool = True
) -> TrainConfig:
    """The validated config that continues the run in ``run_dir``: its saved config with
    ``overrides`` (``key=value`` strings, Hydra's dotted syntax) applied. Raises
    ``CheckpointError`` for a change of a locked field or of a config group. With ``echo``,
    prints each change (a changed cost limit is named as such)."""
    groups = sorted(
        {o.split("=", 1)[0].lstrip("+~") for o in overrides}
        & {*CONFIG_GROUPS, *(f"{g}@_global_" for g in CONFIG_GROUPS)}
    )
    if groups:
        raise CheckpointError(
            f"A resumed run continues with its own config; {', '.join(groups)} would replace a "
            f"whole config group. Give single values instead (e.g. algo.lagrangian_lr=1e-4, "
            f"collector.total_frames=2000000)."
        )
    saved = saved_config(run_dir)
    merged = OmegaConf.merge(
        saved_config_node(saved),
        OmegaConf.from_dotlist([o for o in overrides if not o.startswith("resume=")]),
    )
    merged.resume = str(run_dir)
    cfg = validate(merged)
    current = to_container(cfg)
    # What the saved run had for every field, with the schema's defaults for fields it did not
    # know yet (a checkpoint of an older version): those are the values it ran with.
    before = to_container(validate(saved_config_node(saved)))
    locked = [
        f"{key}: the run has {_get(before, key)!r}, the override gives {_get(current, key)!r}"
        for key in RESUME_LOCKED
        if _get(before, key) != _get(current, key)
    ]
    if locked:
        raise CheckpointError(
            "A resume cannot change what the run's weights, buffer and name depend on "
            "(train a new run instead):\n  " + "\n  ".join(locked)
        )
    if echo:
        for key, (old, new) in config_changes(before, current).items():
            if key == "resume":
                continue
            what = "the cost limit (lambda's target from here on)" if key == "task.cost_limit" else key
            print(f"Resume of {run_dir}: {what} changes from {old!r} to {new!r}")
    return cfg
