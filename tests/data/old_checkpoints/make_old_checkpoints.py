"""Write the old-checkpoint fixtures: runs stopped mid-way by the code at commit 8e0ee0c (before
the algorithms/ and hooks refactor), and what the same runs gave uninterrupted.

    git worktree add /tmp/s3rl-8e0ee0c 8e0ee0c
    PYTHONPATH=/tmp/s3rl-8e0ee0c python tests/data/old_checkpoints/make_old_checkpoints.py

It runs only with that version of the code (it forces the ``critic_eval`` keyword that
``SACLagLoss`` had then). For each case, ``<case>/run/`` is the stopped run's directory
(``config.json`` in the flat ``AlgoConfig`` of that version, ``metrics.csv``, its checkpoints)
and ``<case>/expected/`` the ``metrics.csv`` and ``final_eval.json`` of the same command never
stopped. ``tests/trainer/test_old_checkpoints.py`` resumes each run with today's code and
expects the uninterrupted run's files. Every ``SACLagLoss`` here evaluates its critics with
``critic_eval="vmap"``, the one evaluation the loss kept, so that the resumed run can be
identical (the others round differently).
"""

from __future__ import annotations

import functools
import shutil
import tempfile
from pathlib import Path

from hydra import compose, initialize_config_dir

from s3rl_torchrl.objectives import sac_lag
from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import Trainer, register_configs, train, validate

HERE = Path(__file__).resolve().parent
# (case, overrides, the gradient step after which the run is stopped: mid-epoch)
CASES = [
    ("s3rl", ["algo=s3rl"], 37),
    ("ddpg_lag", ["algo=ddpg_lag"], 37),
    ("ppo_lag", ["algo=ppo_lag"], 40),
]
COMMON = [
    "experiment=tiny",
    "task=SafetyHopperVelocity-v1",
    "logger=none",
    "collector.total_frames=600",
    "algo.buffer_size=600",
]


def force_vmap_critics() -> None:
    init = sac_lag.SACLagLoss.__init__

    @functools.wraps(init)
    def forced(self, *args, **kwargs):
        kwargs["critic_eval"] = "vmap"
        init(self, *args, **kwargs)

    sac_lag.SACLagLoss.__init__ = forced


def stop_after_step(step: int) -> None:
    original = Trainer._gradient_step

    def step_then_stop(self):
        original(self)
        if self.counters.grad_steps == step:
            self.stop.requested = True

    Trainer._gradient_step = step_then_stop


def main() -> None:
    force_vmap_critics()
    register_configs()
    original_step = Trainer._gradient_step
    for case, overrides, step in CASES:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = validate(compose(config_name="train", overrides=[*COMMON, *overrides]))
        out = HERE / case
        shutil.rmtree(out, ignore_errors=True)
        with tempfile.TemporaryDirectory() as tmp:
            train(cfg, Path(tmp) / "full")
            (out / "expected").mkdir(parents=True)
            for name in ("metrics.csv", "final_eval.json"):
                shutil.copy(Path(tmp) / "full" / name, out / "expected" / name)
            stop_after_step(step)
            part = train(cfg, Path(tmp) / "part")
            Trainer._gradient_step = original_step
            assert part.status == "interrupted", part.status
            shutil.copytree(Path(tmp) / "part", out / "run")
        print(f"{case}: stopped at {part.counters.frames} frames, {step} gradient steps")


if __name__ == "__main__":
    main()
