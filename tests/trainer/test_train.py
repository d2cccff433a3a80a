"""End-to-end training runs on tiny settings: every algo, counters, files, resume, signals."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest
import torch

from s3rl_torchrl.algorithms import family_of
from s3rl_torchrl.trainer import Trainer, train
from s3rl_torchrl.trainer.config import ALGO_NAMES
from s3rl_torchrl.trainer.metrics import read_metrics

FINAL_EVAL_KEYS = {
    "reward_mean", "reward_std", "cost_mean", "cost_std", "length_mean", "safe_occupancy",
    "episodes", "episode_rewards", "episode_costs", "episode_lengths", "episode_safe_steps",
    "best_feasible",  # the best-feasible checkpoint's evaluation (tests/trainer/test_best_feasible)
}


def expected_grad_steps(cfg) -> int:
    """The schedule by hand. Off-policy: update_per_step per frame of every batch that ends at
    or after init_random_frames (FSRL starts learning after the warm-up). On-policy (PPO):
    ppo_epochs passes of ceil(frames / batch_size) minibatches over every batch."""
    c = cfg.collector
    if family_of(cfg.algo).name == "ppo":
        batches = c.total_frames // c.frames_per_batch
        return batches * cfg.algo.ppo_epochs * -(-c.frames_per_batch // cfg.algo.batch_size)
    ends = range(c.frames_per_batch, c.total_frames + 1, c.frames_per_batch)
    owed = sum(cfg.algo.update_per_step * c.frames_per_batch for end in ends
               if end >= c.init_random_frames)
    return int(owed)


@pytest.mark.parametrize("algo", ALGO_NAMES)
def test_tiny_run_per_algo(algo, tiny_config, tmp_path):
    # Swimmer-v1 pays costs under a random policy now and then: both strata fill up, so the
    # contrastive phase runs and lambda moves.
    cfg = tiny_config(f"algo={algo}", "task=SafetySwimmerVelocity-v1", "task.cost_limit=0")
    result = train(cfg, tmp_path)
    c = result.counters
    assert result.status == "finished"
    assert c.frames == cfg.collector.total_frames
    assert c.grad_steps == expected_grad_steps(cfg)
    assert c.epochs == cfg.collector.total_frames // cfg.collector.frames_per_epoch

    final = json.loads((tmp_path / "final_eval.json").read_text())
    assert set(final) == FINAL_EVAL_KEYS and final["episodes"] == cfg.eval.final_episodes
    # The per-episode values are the ones the summary statistics were computed from.
    assert len(final["episode_rewards"]) == cfg.eval.final_episodes
    assert final["reward_mean"] == pytest.approx(np.mean(final["episode_rewards"]))
    assert final["cost_std"] == pytest.approx(np.std(final["episode_costs"]))
    assert final["safe_occupancy"] == pytest.approx(
        100 * sum(final["episode_safe_steps"]) / sum(final["episode_lengths"])
    )
    rows = read_metrics(tmp_path)
    assert [int(r["frames"]) for r in rows] == [200, 400, 600]
    assert (tmp_path / "checkpoints" / "latest" / "state.pt").is_file()
    assert (tmp_path / "config.json").is_file()

    if algo.startswith("s3rl"):
        assert c.contrastive_phases > 0
        assert rows[-1]["contrastive/loss_infonce"] != "nan"
    else:
        assert c.contrastive_phases == 0
    lagrangian = [float(r["lagrangian"]) for r in rows]
    family = family_of(cfg.algo).name
    if cfg.algo.lagrangian != "none":
        # Swimmer episodes last 1000 steps: none ends in 600 frames, so lambda never moves.
        assert c.lagrangian_updates == 0 and lagrangian == [0.0, 0.0, 0.0]
        # The cost critic trains and its loss is logged.
        cost_key = {"ddpg": "loss_cost_value", "sac": "loss_cost_qvalue", "ppo": "loss_cost_critic"}
        assert all(np.isfinite(float(r[f"train/{cost_key[family]}"])) for r in rows)
    else:
        assert result.final_eval is not None and lagrangian == [0.0, 0.0, 0.0]
    actor_key = "train/loss_objective" if family == "ppo" else "train/loss_actor"
    assert all(np.isfinite(float(r[actor_key])) for r in rows)


@pytest.mark.parametrize("algo", ["ddpg_lag", "ddpg"])
def test_ddpg_collects_with_noise_and_evaluates_the_actor(algo, tiny_config, tmp_path):
    from torchrl.envs.utils import ExplorationType, set_exploration_type
    from torchrl.objectives import DDPGLoss

    from s3rl_torchrl.objectives import DDPGLagLoss

    trainer = Trainer(tiny_config(f"algo={algo}"), tmp_path)
    agent = trainer.agent
    assert type(agent.loss) is (DDPGLagLoss if algo == "ddpg_lag" else DDPGLoss)
    obs = trainer.train_env.reset()
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        deterministic = agent.actor(obs.clone())["action"]
        assert torch.equal(agent.policy(obs.clone())["action"], deterministic)
    torch.manual_seed(0)
    with set_exploration_type(ExplorationType.RANDOM):  # the collector's exploration type
        noisy = agent.policy(obs.clone())["action"]
    # Gaussian noise of std sigma * (high - low) / 2, then clipped to the action bounds.
    spec = trainer.train_env.action_spec_unbatched
    half_range = (spec.space.high - spec.space.low) / 2
    torch.manual_seed(0)
    noise = torch.randn_like(deterministic) * trainer.cfg.algo.exploration_noise * half_range
    expected = (deterministic + noise).clamp(spec.space.low, spec.space.high)
    assert not torch.equal(noisy, deterministic)
    assert torch.allclose(noisy, expected, atol=1e-6)


@pytest.mark.parametrize("algo", ["sac_lag", "ppo_lag"])
def test_lagrangian_updates_once_per_batch_with_finished_episodes(algo, tiny_config, tmp_path):
    # Hopper falls within ~20 random steps: every batch ends episodes. A zero cost limit and
    # costs under a random policy make the PID output positive.
    cfg = tiny_config(f"algo={algo}", "task=SafetyHopperVelocity-v0", "task.cost_limit=0")
    seen = []
    result = train(cfg, tmp_path, on_epoch_end=lambda t, row: seen.append(row["lagrangian"]))
    batches = cfg.collector.total_frames // cfg.collector.frames_per_batch
    assert result.counters.lagrangian_updates == batches
    assert result.counters.episodes > batches


def _counters(result):
    c = dict(vars(result.counters))
    return c


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["s3rl", "ddpg_lag", "ppo_lag"])
def test_resume_at_epoch_end_matches_uninterrupted_run(algo, tiny_config, tmp_path):
    cfg = tiny_config(f"algo={algo}", "task=SafetySwimmerVelocity-v1")
    full = train(cfg, tmp_path / "full")

    def stop_after_first_epoch(trainer: Trainer, row):
        if row["epoch"] == 1:
            trainer.stop.requested = True

    part = train(cfg, tmp_path / "part", on_epoch_end=stop_after_first_epoch)
    assert part.status == "interrupted" and part.counters.frames == 200
    assert not (tmp_path / "part" / "final_eval.json").exists()

    cfg.resume = str(tmp_path / "part")
    resumed = train(cfg, tmp_path / "ignored")
    assert resumed.status == "finished" and resumed.run_dir == tmp_path / "part"
    assert _counters(resumed) == _counters(full)
    assert [r["frames"] for r in read_metrics(tmp_path / "part")] == ["200", "400", "600"]
    assert (tmp_path / "part" / "final_eval.json").is_file()


@pytest.mark.slow
def test_interrupt_between_gradient_steps_owes_the_rest(tiny_config, tmp_path, monkeypatch):
    cfg = tiny_config("algo=sac_lag")
    full = train(cfg, tmp_path / "full")

    original = Trainer._gradient_step

    def stop_at_step_40(self):
        original(self)
        if self.counters.grad_steps == 40:
            self.stop.requested = True

    monkeypatch.setattr(Trainer, "_gradient_step", stop_at_step_40)
    part = train(cfg, tmp_path / "part")
    monkeypatch.setattr(Trainer, "_gradient_step", original)
    assert part.status == "interrupted"
    assert part.counters.grad_steps == 40 and part.counters.pending_updates > 0

    cfg.resume = str(tmp_path / "part")
    resumed = train(cfg, tmp_path / "ignored")
    assert _counters(resumed) == _counters(full)
    assert [r["frames"] for r in read_metrics(tmp_path / "part")] == ["200", "400", "600"]


@pytest.mark.slow
def test_crash_after_checkpoint_drops_unsaved_metric_rows(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=800", "save_interval=2")

    def crash_at_epoch_3(trainer, row):
        if row["epoch"] == 3:
            raise RuntimeError("simulated crash")

    with pytest.raises(RuntimeError, match="simulated crash"):
        train(cfg, tmp_path, on_epoch_end=crash_at_epoch_3)
    # Epoch 3 was logged, but the last checkpoint is epoch 2's.
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200", "400", "600"]
    cfg.resume = str(tmp_path)
    train(cfg, tmp_path / "ignored")
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200", "400", "600", "800"]


def test_sigterm_writes_a_checkpoint_and_stops(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac")
    previous = signal.getsignal(signal.SIGTERM)

    def send_sigterm(trainer, row):
        os.kill(os.getpid(), signal.SIGTERM)

    result = train(cfg, tmp_path, on_epoch_end=send_sigterm)
    assert result.status == "interrupted" and result.counters.epochs == 1
    state = torch.load(tmp_path / "checkpoints/latest/state.pt", weights_only=True)
    assert state["counters"]["frames"] == 200
    assert signal.getsignal(signal.SIGTERM) == previous  # handler restored


def test_resume_rejects_a_different_network(tiny_config, tmp_path):
    from s3rl_torchrl.trainer import CheckpointError

    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    metrics_before = (tmp_path / "metrics.csv").read_text()
    other = tiny_config("algo=sac", "collector.total_frames=200", "network.actor_hidden=[64,64]")
    other.resume = str(tmp_path)
    with pytest.raises(CheckpointError, match="network.actor_hidden"):
        train(other, tmp_path / "x")
    assert (tmp_path / "metrics.csv").read_text() == metrics_before  # nothing lost


def test_resuming_a_finished_run_changes_nothing(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    first = train(cfg, tmp_path)
    cfg.resume = str(tmp_path)
    again = train(cfg, tmp_path / "ignored")
    assert again.status == "finished" and _counters(again) == _counters(first)
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200"]


@pytest.mark.slow
def test_fsrl_update_order_trains_the_same_schedule(tiny_config, tmp_path):
    cfg = tiny_config("algo=s3rl", "algo.update_order=fsrl", "task=SafetySwimmerVelocity-v1")
    result = train(cfg, tmp_path)
    assert result.counters.grad_steps == expected_grad_steps(cfg)
    assert all(r["train/loss_actor"] != "nan" for r in read_metrics(tmp_path))


@pytest.mark.slow
@pytest.mark.parametrize("update_order", ["joint", "fsrl"])
def test_compiled_update_trains_the_same_schedule(
    update_order, tiny_config, tmp_path, monkeypatch
):
    # compile=true: the loss (joint) or its two halves (fsrl) go through torch.compile.
    from s3rl_torchrl.trainer import loop

    wrapped = []

    def recording_compile(fn):
        compiled = compile_loss(fn)
        wrapped.append((fn, compiled))
        return compiled

    compile_loss = loop.compile_loss
    monkeypatch.setattr(loop, "compile_loss", recording_compile)
    cfg = tiny_config(
        "algo=sac_lag",
        f"algo.update_order={update_order}",
        "compile=true",
        "collector.total_frames=300",
        "collector.frames_per_epoch=300",
    )
    trainer = Trainer(cfg, tmp_path)
    loss = trainer.agent.loss
    expected = [loss] if update_order == "joint" else [loss.qvalue_v2_loss, loss.actor_loss]
    assert [fn for fn, _ in wrapped] == expected
    assert all(hasattr(fn, "_torchdynamo_orig_callable") or hasattr(fn, "_orig_mod")
               for _, fn in wrapped)
    from torch._dynamo.utils import counters

    counters.clear()
    result = trainer.run()
    assert counters["stats"]["unique_graphs"] >= 1  # dynamo did capture the loss
    assert result.counters.grad_steps == expected_grad_steps(cfg) > 0
    (row,) = read_metrics(tmp_path)
    for key in ("train/loss_actor", "train/loss_qvalue", "train/loss_cost_qvalue"):
        assert torch.isfinite(torch.tensor(float(row[key])))


@pytest.mark.slow
@pytest.mark.parametrize("algo, n_step", [("s3rl", 2), ("sac", 1), ("ddpg_lag", 2), ("ddpg", 1)])
def test_buffer_stores_only_what_is_read_back(algo, n_step, tiny_config, tmp_path):
    cfg = tiny_config(f"algo={algo}", f"algo.n_step={n_step}", "collector.total_frames=300",
                      "diagnostics.probes=true")
    trainer = Trainer(cfg, tmp_path)
    trainer.run()
    stored = set(trainer.replay_buffer[:].keys(True, True))
    # The losses' inputs (n-step reward and discount exponent), the safe/unsafe label the
    # sampler partitions on, the cost-to-go the graded probe reads (the contrastive encoder
    # and the probes read the observation) ...
    needed = {
        "observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
        ("next", "terminated"), ("next", "safe"), ("next", "cost_to_go"),
        "index",  # torchrl's TensorDict writer stores each transition's slot
    }
    if algo in ("s3rl", "ddpg_lag"):
        needed.add(("next", "cost"))
    if n_step > 1:
        needed.add("steps_to_next_obs")
    assert stored == needed
    # ... and none of what the collector, the transforms and the policy also write.
    collected = set(trainer.train_env.rollout(3, trainer.agent.policy).keys(True, True))
    policy_outputs = {"embedding"} | (
        set() if "ddpg" in algo else {"loc", "scale", "action_log_prob"}
    )
    assert policy_outputs | {("next", "episode_reward"), ("next", "step_count")} <= collected


def test_critics_keep_their_own_initialisation(tiny_config):
    # One module per critic: every critic keeps FSRL's orthogonal init (torchrl would re-draw
    # copies of a single module uniformly) and the critics differ from each other.
    from s3rl_torchrl.trainer.builders import build_agent, build_envs, build_replay_buffer

    cfg = tiny_config("algo=sac_lag", "algo.cost_critic_read=max", "algo.cost_target_read=mean")
    env, _ = build_envs(cfg)  # no graded label: the train env reads no margin
    agent = build_agent(cfg, env, build_replay_buffer(cfg.algo))
    # The config's reads reach the loss (tests/objectives/test_sac_lag.py: what each reads).
    assert (agent.loss.cost_critic_read, agent.loss.cost_target_read) == ("max", "mean")
    for name in ("qvalue_network_params", "cost_qvalue_network_params"):
        params = getattr(agent.loss, name)
        first_layer = [p for k, p in params.items(True, True) if p.ndim == 3][0]  # [2, out, in]
        assert not torch.equal(first_layer[0], first_layer[1])
        for weight in first_layer:  # 32 x 23: orthonormal columns
            gram = weight.T @ weight
            torch.testing.assert_close(gram, torch.eye(gram.shape[0]), atol=1e-5, rtol=0)


def test_new_run_into_an_existing_run_dir_is_refused(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=200")
    train(cfg, tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    with pytest.raises(FileExistsError, match="resume="):
        train(tiny_config("algo=sac_lag", "collector.total_frames=200"), tmp_path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before


def test_run_shorter_than_an_epoch_leaves_a_loadable_checkpoint(tiny_config, tmp_path, capsys):
    # 300 frames, epochs of 400: the run's end closes a shorter last epoch (a metrics row and
    # the final checkpoint), whatever the epoch length.
    from s3rl_torchrl.trainer.evaluate_checkpoint import evaluate_checkpoint

    cfg = tiny_config("algo=sac_lag", "collector.total_frames=300",
                      "collector.frames_per_epoch=400")
    result = train(cfg, tmp_path)
    assert result.counters.epochs == 1
    assert result.counters.grad_steps == expected_grad_steps(cfg) == 50
    (row,) = read_metrics(tmp_path)
    assert (row["frames"], row["epoch"], row["grad_steps"]) == ("300", "1", "50")
    assert (tmp_path / "checkpoints" / "latest" / "state.pt").is_file()
    # The final table says how much the policy was trained.
    out = capsys.readouterr().out
    assert "| gradient steps |" in out and "seed 10 | 2 |" in out and " | 50 |" in out

    evaluated, train_cfg = evaluate_checkpoint(tmp_path, episodes=1, num_envs=1, max_steps=10)
    assert evaluated.episodes == 1 and evaluated.length_mean == 10.0
    assert train_cfg.collector.total_frames == 300


def test_last_partial_epoch_is_logged_and_saved(tiny_config, tmp_path):
    # 500 frames in epochs of 200: rows at 200, 400 and the run's end (500); the last
    # checkpoint holds the finished run (resuming it only evaluates).
    # Batches of 400: the 2-step transform holds back 2 frames per env copy, so the buffer
    # holds 2 x (50 k - 2) transitions after k batches, >= 400 only after the 5th: 25 steps.
    cfg = tiny_config("algo=sac", "collector.total_frames=500", "save_interval=5",
                      "algo.batch_size=400")
    first = train(cfg, tmp_path)
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200", "400", "500"]
    assert first.counters.epochs == 3 and first.counters.grad_steps == 25
    cfg.resume = str(tmp_path)
    again = train(cfg, tmp_path / "ignored")
    assert _counters(again) == _counters(first)
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200", "400", "500"]


def test_extending_a_finished_run_continues_it(tiny_config, tmp_path):
    # A 400-frame run carried to 600 frames: the extended run continues from its checkpoint,
    # and its earlier final evaluation is kept under another name; config.json records the
    # resume (frames, and what changed) and holds the config the run continued with.
    from s3rl_torchrl.trainer import CheckpointError

    cfg = tiny_config("algo=sac_lag", "collector.total_frames=400")
    first = train(cfg, tmp_path)
    final_400 = (tmp_path / "final_eval.json").read_text()

    shorter = tiny_config("algo=sac_lag", "collector.total_frames=300")
    shorter.resume = str(tmp_path)
    with pytest.raises(CheckpointError, match="collector.total_frames.*>= 400"):
        train(shorter, tmp_path / "x")
    assert (tmp_path / "final_eval.json").read_text() == final_400  # nothing lost

    longer = tiny_config("algo=sac_lag", "collector.total_frames=600", "compile=false")
    longer.resume = str(tmp_path)
    extended = train(longer, tmp_path / "ignored")
    assert extended.status == "finished" and extended.counters.frames == 600
    assert extended.counters.grad_steps == first.counters.grad_steps + 0.25 * 200
    assert [r["frames"] for r in read_metrics(tmp_path)] == ["200", "400", "600"]
    assert (tmp_path / "final_eval_400.json").read_text() == final_400
    assert json.loads((tmp_path / "final_eval.json").read_text())["episodes"] == 2
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["collector"]["total_frames"] == 600
    assert config["resumes"] == [
        {"frames": 400, "changed": {"collector.total_frames": [400, 600]}, "exact": True}
    ]


def test_a_resume_records_what_it_changed(tiny_config, tmp_path):
    cfg = tiny_config("algo=sac", "collector.total_frames=400")

    def stop_after_first_epoch(trainer: Trainer, row):
        trainer.stop.requested = True

    train(cfg, tmp_path, on_epoch_end=stop_after_first_epoch)
    resumed = tiny_config("algo=sac", "collector.total_frames=400", "threads=2")
    resumed.resume = str(tmp_path)
    train(resumed, tmp_path / "ignored")
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["threads"] == 2
    assert config["resumes"] == [{"frames": 200, "changed": {"threads": [1, 2]}, "exact": True}]
