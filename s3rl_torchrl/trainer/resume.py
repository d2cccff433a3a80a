"""Resume, in one place: what a resume reads, checks and restores.

A run continues from its checkpoint (``resume=<run dir>``, or ``resume=auto``: the command's own
directory when it holds a run, :func:`holds_run`). Everything a resume does happens here, in
this order:

1. the config (:func:`resume_config`, the recipe): ``s3rl-train resume=<run dir>`` continues the
   run with the config its checkpoint was written with; every other override on that command
   line is a *change* (``algo.lagrangian_lr=1e-4``, ``collector.total_frames=2000000`` to extend
   a run), printed and recorded in the run's ``config.json`` (``resumes``). What the saved
   weights, buffer and identity of the run depend on cannot change (:data:`RESUME_LOCKED`):
   the task, the algorithm, the seed, the network sizes, the buffer layout. Config groups
   (``task=...``, ``experiment=...``) cannot be given either: they would replace many values at
   once;
2. the checkpoint (:meth:`Resume.read`, before the trainer builds or writes anything): read and
   verified against its manifest (``checkpoint.py``), its config checked against the run's
   (:func:`check_compatible`, :func:`check_total_frames`); it names the run directory;
3. the trainer's state (:meth:`Resume.restore`, once the trainer is built): the buffers, then
   :meth:`Trainer.load_state_dict <s3rl_torchrl.trainer.Trainer.load_state_dict>` (networks,
   optimisers, counters, hooks, the envs' snapshots, the random streams), whether the run
   continues exactly (:func:`~s3rl_torchrl.envs.state.exact_restore_unsupported`), what the
   interrupted run logged after its checkpoint cut off (``metrics.py``), the resume recorded
   (:func:`record_resume`).

A group of seeds resumes each seed so (``multiseed.py``), after :func:`check_group`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from s3rl_torchrl.envs.state import (
    SnapshotMismatch,
    exact_restore_unsupported,
    snapshot_mujoco_problem,
)
from s3rl_torchrl.trainer.checkpoint import (
    GROUP_FILE,
    REPLAY_DIR,
    CheckpointError,
    load_checkpoint,
    resolve_checkpoint,
)
from s3rl_torchrl.trainer.config import (
    TrainConfig,
    saved_config_node,
    saved_train_config,
    to_container,
    validate,
)
from s3rl_torchrl.trainer.metrics import CONFIG_FILE, FINAL_EVAL_FILE, cut_back_to_checkpoint

__all__ = [
    "RESUME_LOCKED",
    "Resume",
    "check_compatible",
    "check_group",
    "check_total_frames",
    "holds_run",
    "record_resume",
    "resume_config",
    "saved_config",
]

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


# ------------------------------------------------------------------------------ the checkpoint
def holds_run(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a run to continue (a checkpoint, or a multi-seed group):
    what ``resume=auto`` continues."""
    if (Path(run_dir) / GROUP_FILE).is_file():
        return True
    try:
        resolve_checkpoint(run_dir)
    except CheckpointError:
        return False
    return True


def check_compatible(saved: dict[str, Any], current: dict[str, Any], keys: list[str]) -> None:
    """Fail clearly when a resumed run's config differs where the saved weights depend on it."""

    # _get: None where the family has no such field (PPO's n_step).
    diffs = [
        f"{key}: checkpoint has {_get(saved, key)!r}, the current config has {_get(current, key)!r}"
        for key in keys
        if _get(saved, key) != _get(current, key)
    ]
    if diffs:
        raise CheckpointError(
            "The checkpoint does not match the current configuration:\n  " + "\n  ".join(diffs)
        )


def check_total_frames(cfg: TrainConfig, frames: int) -> None:
    """A resumed run may get a larger ``collector.total_frames`` (extending a finished run),
    never one below the frames it already collected."""
    if cfg.collector.total_frames < frames:
        raise CheckpointError(
            f"Invalid value {cfg.collector.total_frames!r} for 'collector.total_frames': the "
            f"checkpoint has already collected {frames} frames; resume with "
            f"collector.total_frames >= {frames} (larger extends the run)."
        )


def check_group(run_dir: Path, seeds: list[int]) -> None:
    """A multi-seed group resumes from its own directory with its own seeds."""
    group_file = run_dir / GROUP_FILE
    if not group_file.is_file():
        raise CheckpointError(
            f"{run_dir} is not a multi-seed run directory (no {GROUP_FILE}); a "
            "single-seed run resumes without `seeds`."
        )
    saved = json.loads(group_file.read_text())["seeds"]
    if list(saved) != list(seeds):
        raise CheckpointError(
            f"The multi-seed run in {run_dir} has seeds={saved}; resume it with the "
            f"same seeds (got seeds={list(seeds)})."
        )


def check_simulator(state: dict[str, Any]) -> None:
    """Refuse a checkpoint whose env snapshots (the test envs', the training envs', a hook's)
    another MuJoCo release wrote: this one cannot read them (envs/state.py)."""
    hooks = state.get("hooks") or {}
    snapshots = [state.get("test_env"), (state.get("collector") or {}).get("train_env")]
    snapshots += [hook.get("env") for hook in hooks.values() if isinstance(hook, dict)]
    for snapshot in snapshots:
        problem = snapshot_mujoco_problem(snapshot if isinstance(snapshot, dict) else None)
        if problem is not None:
            raise CheckpointError(f"Cannot resume this checkpoint: {problem}.")


@dataclass
class Resume:
    """The checkpoint a run continues from, read, verified and checked against the run's
    config (:meth:`read`); :meth:`restore` puts it into the trainer built for it."""

    cfg: TrainConfig  # the config the run continues with
    state: dict[str, Any]  # the checkpoint's state.pt
    checkpoint_dir: Path  # <run>/checkpoints/latest
    saved: dict[str, Any]  # the config the checkpoint was written with, as this version reads it

    @classmethod
    def read(cls, cfg: TrainConfig) -> Resume:
        """The checkpoint of ``cfg.resume``, refused (:class:`CheckpointError`) when it is
        corrupt or when ``cfg`` changes a locked field or has fewer frames than it collected:
        before anything is built or written."""
        state, checkpoint_dir = load_checkpoint(cfg.resume)
        # The run's config as this version reads it (trainer/config.py: saved_config_node).
        saved = to_container(saved_train_config(state["config"]))
        check_compatible(saved, to_container(cfg), RESUME_LOCKED)
        check_total_frames(cfg, state["counters"]["frames"])
        check_simulator(state)
        return cls(cfg, state, checkpoint_dir, saved)

    @property
    def run_dir(self) -> Path:
        return self.checkpoint_dir.parent.parent  # <run>/checkpoints/latest

    @property
    def frames(self) -> int:
        return self.state["counters"]["frames"]

    def restore(self, trainer) -> None:
        """Put the checkpoint into ``trainer`` (a :class:`~s3rl_torchrl.trainer.Trainer` built
        from :attr:`cfg` into :attr:`run_dir`, before its logger opens a file): its buffers and
        state, then the run's files cut back to the checkpoint and the resume recorded."""
        print(
            f"Resuming {trainer.run_dir} at frame {self.frames} of "
            f"{self.cfg.collector.total_frames}"
        )
        # The buffers first: a hook's state may read them (hooks/base.py).
        trainer.replay_buffer.loads(self.checkpoint_dir / REPLAY_DIR)
        trainer.updates.load(self.checkpoint_dir)
        try:
            trainer.load_state_dict(self.state)
        except SnapshotMismatch as err:  # before any of the run's files is cut back
            raise CheckpointError(f"Cannot resume {trainer.run_dir}: {err}.") from err
        reason = self._inexact_reason(trainer)
        if reason is not None:
            # The n-step windows held back from the last batch would run into the restarted
            # episodes' first steps: they end where their episodes were cut.
            trainer.updates.end_episodes()
            print(
                f"Resuming {trainer.run_dir} inexactly: {reason}; every training episode "
                "restarts here, so the rest of the run differs from an uninterrupted one."
            )
        trainer.inexact_resume = reason
        # What the interrupted run logged after its checkpoint goes, before a logger opens
        # (or, as TensorBoard's does, creates) a file.
        cut_back_to_checkpoint(
            trainer.run_dir, self.state.get("appended_files"), trainer.counters.frames
        )
        record_resume(
            trainer.run_dir, self.saved, to_container(self.cfg), trainer.counters, inexact=reason
        )

    def _inexact_reason(self, trainer) -> str | None:
        """Why the run cannot continue exactly, or None: frames are left to collect and the
        checkpoint has no collector state to continue the training episodes with (a task or
        batching that cannot be snapshot, or a checkpoint written before checkpoints kept the
        envs' state), so every one of them restarts."""
        if self.state.get("collector") is not None or self.frames >= self.cfg.collector.total_frames:
            return None
        return exact_restore_unsupported(trainer.train_env) or (
            "the checkpoint was written before checkpoints kept the envs' state"
        )


# ------------------------------------------------------------------------------ the record
def record_resume(
    run_dir: Path, saved: dict, current: dict, counters: Any, inexact: str | None = None
) -> None:
    """What a resume changed, kept in the run's ``config.json``: it then holds the config the
    run continues with, and under ``resumes`` every resume's frame count and the values it
    changed (``[before, after]``), e.g. ``compile`` or an extended ``collector.total_frames``.
    An extended run's earlier ``final_eval.json`` is kept as ``final_eval_<frames>.json``.
    ``counters``: the trainer's (its ``frames``)."""
    path = run_dir / CONFIG_FILE
    history = json.loads(path.read_text()).get("resumes", []) if path.is_file() else []
    changed = {
        key: [before, after]
        for key, (before, after) in config_changes(saved, current).items()
        if key != "resume"
    }
    entry: dict[str, Any] = {"frames": counters.frames, "changed": changed, "exact": inexact is None}
    if inexact is not None:
        entry["inexact_reason"] = inexact
    history.append(entry)
    path.write_text(json.dumps({**current, "resumes": history}, indent=2))
    final = run_dir / FINAL_EVAL_FILE
    if final.is_file() and current["collector"]["total_frames"] > counters.frames:
        final.rename(run_dir / f"final_eval_{counters.frames}.json")
