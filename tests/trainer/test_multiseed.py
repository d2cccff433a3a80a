"""Several seeds in one process (seeds=[...]): per-seed runs, equivalence, resume, checks."""

from __future__ import annotations

import json
import shutil

import pytest
import torch
from tensordict import TensorDict

from s3rl_torchrl.algorithms import ALGORITHMS, SAC
from s3rl_torchrl.trainer import (
    CheckpointError,
    ConfigError,
    MultiSeedTrainer,
    Trainer,
    train,
    train_seeds,
)
from s3rl_torchrl.trainer.metrics import read_metrics
from tests.trainer.test_train import FINAL_EVAL_KEYS, expected_grad_steps

SEEDS = [11, 12]


# The SAC family (the DDPG family is refused: test_bad_seeds_fail_before_training).
@pytest.mark.parametrize("algo", [name for name, a in ALGORITHMS.items() if a.family is SAC])
def test_each_seed_writes_a_single_runs_files(algo, tiny_config, tmp_path):
    # Swimmer-v1 pays costs under a random policy now and then: the contrastive phase runs.
    cfg = tiny_config(f"algo={algo}", "task=SafetySwimmerVelocity-v1", "task.cost_limit=0",
                      f"seeds=[{SEEDS[0]},{SEEDS[1]}]")
    result = train_seeds(cfg, tmp_path)
    assert result.status == "finished" and len(result.runs) == 2
    assert json.loads((tmp_path / "seeds.json").read_text())["seeds"] == SEEDS
    for seed, run in zip(SEEDS, result.runs, strict=True):
        run_dir = tmp_path / f"seed{seed}"
        assert run.run_dir == run_dir
        c = run.counters
        assert c.frames == cfg.collector.total_frames
        assert c.grad_steps == expected_grad_steps(cfg)
        assert (c.contrastive_phases > 0) == algo.startswith("s3rl")
        config = json.loads((run_dir / "config.json").read_text())
        assert config["seed"] == seed and config["seeds"] is None
        final = json.loads((run_dir / "final_eval.json").read_text())
        assert set(final) == FINAL_EVAL_KEYS
        assert [int(r["frames"]) for r in read_metrics(run_dir)] == [200, 400, 600]
        state = torch.load(run_dir / "checkpoints/latest/state.pt", weights_only=True)
        assert state["config"]["seed"] == seed
    # Independent agents: different seeds, different weights.
    first = [
        torch.load(tmp_path / f"seed{s}/checkpoints/latest/state.pt", weights_only=True)["loss"]
        for s in SEEDS
    ]
    key = next(k for k in first[0] if k.startswith("actor_network_params"))
    assert not torch.equal(first[0][key], first[1][key])


def test_seed_k_follows_the_single_run_with_seed_k(tiny_config, tmp_path):
    """Same initial parameters; same batches and normal draws (one random stream per seed), so
    the first epoch's 25 gradient steps give the single run's losses up to float rounding (the
    batched kernels round differently; over many steps the runs drift apart, docs/recipes.md)."""
    overrides = ("algo=s3rl", "collector.total_frames=200")
    cfg = tiny_config(*overrides, f"seed={SEEDS[1]}")
    group_cfg = tiny_config(*overrides, f"seeds=[{SEEDS[0]},{SEEDS[1]}]")

    single = Trainer(cfg, tmp_path / "single")
    group = MultiSeedTrainer(group_cfg, tmp_path / "group")
    member = group.members[1]
    own = TensorDict.from_module(member.agent.loss).flatten_keys()
    for key, value in TensorDict.from_module(single.agent.loss).flatten_keys().items():
        assert torch.equal(own[key], value), key

    single_row = single.run().history[0]
    group_row = group.run().runs[1].history[0]
    assert single_row["grad_steps"] == group_row["grad_steps"] == 25
    for key, value in single_row.items():
        if key.startswith("train/") and key != "train/episodes":
            assert group_row[key] == pytest.approx(value, rel=1e-4, abs=1e-5, nan_ok=True), key
    single_state = torch.load(tmp_path / "single/checkpoints/latest/state.pt", weights_only=True)
    group_state = torch.load(
        tmp_path / f"group/seed{SEEDS[1]}/checkpoints/latest/state.pt", weights_only=True
    )
    for key, value in single_state["loss"].items():
        torch.testing.assert_close(group_state["loss"][key], value, rtol=1e-3, atol=1e-4)


def test_group_resume_matches_an_uninterrupted_group(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac_lag", f"seeds=[{SEEDS[0]},{SEEDS[1]}]")
    full = train_seeds(cfg, tmp_path / "full")

    def stop_after_first_epoch(trainer: Trainer, row):
        if row["epoch"] == 1:
            trainer.stop.requested = True

    part = train_seeds(cfg, tmp_path / "part", on_epoch_end=stop_after_first_epoch)
    assert part.status == "interrupted"
    assert [r.counters.frames for r in part.runs] == [200, 200]

    # A seed's checkpoint is a single run's: the single-seed loop resumes it as it is.
    shutil.copytree(tmp_path / "part" / f"seed{SEEDS[0]}", tmp_path / "single")
    single = tiny_config("algo=sac_lag", f"seed={SEEDS[0]}")
    single.resume = str(tmp_path / "single")
    assert vars(train(single, tmp_path / "ignored").counters) == vars(full.runs[0].counters)

    cfg.resume = str(tmp_path / "part")
    resumed = train_seeds(cfg, tmp_path / "ignored")
    assert resumed.status == "finished" and resumed.run_dir == tmp_path / "part"
    for seed, run, reference in zip(SEEDS, resumed.runs, full.runs, strict=True):
        assert vars(run.counters) == vars(reference.counters)
        run_dir = tmp_path / "part" / f"seed{seed}"
        assert [r["frames"] for r in read_metrics(run_dir)] == ["200", "400", "600"]
        assert (run_dir / "final_eval.json").is_file()


def test_resume_needs_the_groups_seeds(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=200", "seeds=[11,12]")
    train_seeds(cfg, tmp_path)
    cfg.seeds, cfg.resume = [11, 13], str(tmp_path)
    with pytest.raises(CheckpointError, match="seeds=\\[11, 12\\]"):
        MultiSeedTrainer(cfg, tmp_path)
    cfg.seeds, cfg.resume = [11, 12], None
    with pytest.raises(FileExistsError, match="multi-seed run"):
        MultiSeedTrainer(cfg, tmp_path)
    # A single-seed resume (or s3rl-eval) of the group's directory says how to name it.
    cfg.seeds, cfg.resume = None, str(tmp_path)
    with pytest.raises(CheckpointError, match=r"multi-seed run \(seeds \[11, 12\]\).*seed11"):
        Trainer(cfg, tmp_path)


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (["seeds=[]"], "at least one seed"),
        (["seeds=[10,10]"], "distinct"),
        (["seeds=[10,20]", "algo.update_order=fsrl"], "update_order=joint"),
        (["seeds=[10,20]", "algo=ddpg_lag"], "SAC family only.*'ddpg_lag'"),
        (["seeds=[10,20]", "algo=s3rl_ddpg_lag"], "SAC family only"),
        # On-policy PPO has no batched update: refused, naming the algos that have one.
        (["seeds=[10,20]", "algo=ppo_lag"], r"SAC family only \(s3rl, sac_lag, .*'ppo_lag'"),
        (["seeds=[10,20]", "algo=s3rl_ppo_lag"], "SAC family only"),
    ],
)
def test_bad_seeds_fail_before_training(overrides, match, tiny_config):
    with pytest.raises(ConfigError, match=match):
        tiny_config(*overrides)


def test_cli_trains_a_group(tmp_path):
    from tests.trainer.test_cli import TINY, run

    # The default output directory names the group's seeds.
    out = run("s3rl-train", *TINY, "algo=sac", "seeds=[11,12]", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    (run_dir,) = (tmp_path / "outputs/sac/SafetyHalfCheetahVelocity-v1/seeds11-12").iterdir()
    for seed in SEEDS:
        assert f"sac SafetyHalfCheetahVelocity-v1 seed {seed}" in out.stdout
        assert (run_dir / f"seed{seed}" / "final_eval.json").is_file()
    out = run("s3rl-train", *TINY, "algo=sac", "seeds=[11,11]", f"hydra.run.dir={run_dir}",
              cwd=tmp_path)
    assert out.returncode == 2 and "distinct" in out.stderr


def test_each_seed_closes_a_shorter_last_epoch(tiny_config, tmp_path):
    # 500 frames in epochs of 200: as a single run, every seed logs rows at 200, 400 and the
    # run's end (500) and saves its final checkpoint there.
    cfg = tiny_config("algo=sac", "collector.total_frames=500", f"seeds=[{SEEDS[0]},{SEEDS[1]}]")
    result = train_seeds(cfg, tmp_path)
    assert result.status == "finished"
    for seed in SEEDS:
        run_dir = tmp_path / f"seed{seed}"
        assert [int(r["frames"]) for r in read_metrics(run_dir)] == [200, 400, 500]
        state = torch.load(run_dir / "checkpoints/latest/state.pt", weights_only=True)
        assert state["counters"]["frames"] == 500 and state["counters"]["epochs"] == 3
