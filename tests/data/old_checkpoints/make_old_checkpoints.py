"""Write the old-checkpoint fixtures: runs stopped mid-way by the code at commit 8e0ee0c (before
the algorithms/ and hooks refactor), and what the same runs gave uninterrupted.

    git worktree add /tmp/s3rl-8e0ee0c 8e0ee0c
    PYTHONPATH=/tmp/s3rl-8e0ee0c python tests/data/old_checkpoints/make_old_checkpoints.py

It runs only with that version of the code (it forces the ``critic_eval`` keyword that
``SACLagLoss`` had then). Its evaluation counts episodes by today's rule (each env copy's first
episode of a rollout, ``s3rl_torchrl/trainer/evaluation.py`` of this checkout, loaded by path):
the old rule also counted the episodes after a fall, and a resumed run evaluates by today's.
``--expected-only`` rewrites ``<case>/expected/`` alone and keeps the stopped runs: their one
episode per epoch is the same by both rules (2026-12-01, after the evaluation change). For each
case, ``<case>/run/`` is the stopped run's directory
(``config.json`` in the flat ``AlgoConfig`` of that version, ``metrics.csv``, its checkpoints)
and ``<case>/expected/`` the ``metrics.csv`` and ``final_eval.json`` of the same command never
stopped. ``tests/trainer/test_old_checkpoints.py`` resumes each run with today's code and
expects the uninterrupted run's files. Every ``SACLagLoss`` here evaluates its critics with
``critic_eval="vmap"``, the one evaluation the loss kept, so that the resumed run can be
identical (the others round differently).
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import shutil
import sys
import tempfile
from pathlib import Path

from hydra import compose, initialize_config_dir

from s3rl_torchrl.objectives import sac_lag
from s3rl_torchrl.recipes import config_dir
from s3rl_torchrl.trainer import Trainer, evaluation, register_configs, train, validate

HERE = Path(__file__).resolve().parent
TODAYS_EVALUATION = HERE.parents[2] / "s3rl_torchrl" / "trainer" / "evaluation.py"
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


def count_episodes_by_todays_rule() -> None:
    spec = importlib.util.spec_from_file_location("todays_evaluation", TODAYS_EVALUATION)
    today = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = today  # its dataclasses look their module up there
    spec.loader.exec_module(today)
    evaluation.episode_statistics = today.episode_statistics


def stop_after_step(step: int) -> None:
    original = Trainer._gradient_step

    def step_then_stop(self):
        original(self)
        if self.counters.grad_steps == step:
            self.stop.requested = True

    Trainer._gradient_step = step_then_stop


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--expected-only", action="store_true",
                        help="rewrite <case>/expected/ only, keeping the stopped runs")
    args = parser.parse_args()
    force_vmap_critics()
    count_episodes_by_todays_rule()
    register_configs()
    original_step = Trainer._gradient_step
    for case, overrides, step in CASES:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = validate(compose(config_name="train", overrides=[*COMMON, *overrides]))
        out = HERE / case
        shutil.rmtree(out / "expected" if args.expected_only else out, ignore_errors=True)
        with tempfile.TemporaryDirectory() as tmp:
            train(cfg, Path(tmp) / "full")
            (out / "expected").mkdir(parents=True)
            for name in ("metrics.csv", "final_eval.json"):
                shutil.copy(Path(tmp) / "full" / name, out / "expected" / name)
            if args.expected_only:
                print(f"{case}: expected/ rewritten")
                continue
            stop_after_step(step)
            part = train(cfg, Path(tmp) / "part")
            Trainer._gradient_step = original_step
            assert part.status == "interrupted", part.status
            shutil.copytree(Path(tmp) / "part", out / "run")
        print(f"{case}: stopped at {part.counters.frames} frames, {step} gradient steps")


if __name__ == "__main__":
    main()
