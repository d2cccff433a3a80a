"""research/delivered_policy/selection.md is what summarise.py reads from the exported selection
runs (research/results/delivered_selection), recomputed here from their files by hand."""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import json
from pathlib import Path

import pytest
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "research" / "results" / "delivered_selection"


def _script(name: str):
    """research/delivered_policy/<name>.py as a module (research/ is not a package)."""
    path = ROOT / "research" / "delivered_policy" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_committed_table_is_the_exported_runs_table():
    module = _script("summarise")
    committed = (ROOT / "research" / "delivered_policy" / "selection.md").read_text()
    lines = ["| " + " | ".join(module.HEADER) + " |", "|" + "---|" * len(module.HEADER)]
    lines += ["| " + " | ".join(row) + " |" for row in module.rows(RESULTS)]
    lines += ["", module.pick_optimism(RESULTS)]
    header = module.CANDIDATE_HEADER
    lines += ["", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    tally = module.candidate_tally(RESULTS, module.committed_rewards())
    lines += ["| " + " | ".join(row) + " |" for row in module.candidate_rows(tally)]
    lines += ["", module.choice(tally)]
    assert committed == "\n".join(lines) + "\n"


def test_the_rule_applied_by_hand():
    """The note's rule: most runs within the limit, a tie to the higher median reward ratio,
    a ratio below 0.85 passed over, fewer than 13 of 14 said; undecided until 14 runs each."""
    choice = _script("summarise").choice
    goal = {("goal_omnisafe", "last policy"): (0, 1, None)}  # not a margin/aim candidate
    assert choice({("margin", "last policy"): (3, 3, 1.03), **goal}) == (
        "The rule decides once each of margin, aim has its 14 runs: 3 of 28 have finished.")
    assert choice({("aim", "last policy"): (14, 14, 1.20),
                   ("margin", "last policy"): (13, 13, 0.95), **goal}) == (
        "The rule decides once each of margin, aim has its 14 runs: 27 of 28 have finished.")
    table = {
        ("aim", "delivered pick"): (12, 14, 1.10),
        ("aim", "last policy"): (13, 14, 0.90),
        ("margin", "delivered pick"): (14, 14, 0.80),
        ("margin", "last policy"): (13, 14, 0.95),
        **goal,
    }
    assert choice(table) == (
        "Passed over (reward ratio 0.80 < 0.85): margin, delivered pick (14 of 14). "
        "The rule's choice: margin, last policy (13 of 14 within the limit, reward ratio 0.95).")
    table["margin", "last policy"] = (12, 14, 0.95)
    assert choice(table) == (
        "Passed over (reward ratio 0.80 < 0.85): margin, delivered pick (14 of 14). "
        "The rule's choice: aim, last policy (13 of 14 within the limit, reward ratio 0.90).")
    table["aim", "last policy"] = (11, 14, 0.90)
    assert choice(table) == (
        "Passed over (reward ratio 0.80 < 0.85): margin, delivered pick (14 of 14). "
        "The rule's choice: aim, delivered pick (12 of 14 within the limit, reward ratio 1.10). "
        "Fewer than 13 of 14: the evidence runs with it and the docs state the miss.")
    for key, (kept, runs, _) in list(table.items())[:4]:
        table[key] = (kept, runs, 0.50)
    assert choice(table).endswith("No candidate keeps 0.85 of the reward: the rule chooses none.")


def test_the_rules_numbers_are_the_queues():
    """14 runs per candidate: selection.py's margin/aim groups times its seeds."""
    summarise, selection = _script("summarise"), _script("selection")
    assert set(summarise.RULE_CANDIDATES) == set(selection.CANDIDATES)
    groups = [case for case in selection.CASES if case[2] is selection.CANDIDATES]
    assert summarise.RULE_RUNS == len(groups) * len(selection.SEEDS) == 14


def test_each_candidates_tally_by_hand():
    committed = {}
    for tree in ("safe_sound", "table1"):
        for final_path in (ROOT / "results" / tree).rglob("final_eval.json"):
            config = json.loads((final_path.parent / "config.json").read_text())
            key = (config["algo"]["name"], config["task"]["name"])
            committed.setdefault(key, []).append(json.loads(final_path.read_text())["reward_mean"])
    tally = {}
    for final_path in RESULTS.rglob("final_eval.json"):
        run = final_path.parent
        config = json.loads((run / "config.json").read_text())
        final = json.loads(final_path.read_text())
        rewards = committed[(config["algo"]["name"], config["task"]["name"])]
        reference = sum(rewards) / len(rewards)
        assert len(rewards) == 3
        for protocol, result in (("last policy", final), ("delivered pick", final["delivered"])):
            kept, ratios = tally.setdefault((run.relative_to(RESULTS).parts[0], protocol), ([], []))
            kept.append(result["cost_mean"] <= config["task"]["cost_limit"])
            if reference > 1.0:
                ratios.append(result["reward_mean"] / reference)
    module = _script("summarise")
    computed = module.candidate_tally(RESULTS, module.committed_rewards())
    rows = {(r[0], r[1]): r[2:] for r in module.candidate_rows(computed)}
    assert set(rows) == set(tally)
    for key, (kept, ratios) in tally.items():
        ratios = sorted(ratios)
        middle = len(ratios) // 2
        median = (ratios[middle] if len(ratios) % 2 else (ratios[middle - 1] + ratios[middle]) / 2
                  ) if ratios else None
        assert rows[key] == [f"{sum(kept)} of {len(kept)}", "–" if median is None else f"{median:.2f}"]


def test_each_row_by_hand():
    rows = {(r[0], r[1], r[2], r[3]): r for r in _script("summarise").rows(RESULTS)}
    for final_path in sorted(RESULTS.rglob("final_eval.json")):
        run = final_path.parent
        config = json.loads((run / "config.json").read_text())
        final = json.loads(final_path.read_text())
        key = (run.relative_to(RESULTS).parts[0], config["algo"]["name"],
               config["task"]["name"], str(config["seed"]))
        row = rows[key]
        assert row[5] == f"{final['reward_mean']:.1f} / {final['cost_mean']:.1f}"
        picked = final["delivered"]
        assert row[6].startswith(f"{picked['reward_mean']:.1f} / {picked['cost_mean']:.1f}")
        with (run / "metrics.csv").open() as f:
            metrics = [r for r in csv.DictReader(f)
                       if float(r["frames"]) > 0.8 * config["collector"]["total_frames"]]
        limit = config["task"]["cost_limit"]
        train = [float(r["train/cost"]) for r in metrics]
        over = [float(r["eval/cost"]) > limit for r in metrics]
        assert row[7] == f"{sum(train) / len(train):.1f}"
        assert row[8] == f"{sum(over) / len(over):.2f}"


def test_the_picks_optimism_by_hand():
    """selection.md's line on the picks: each pick's reported cost (final_eval.json's
    `delivered`) minus its candidate's cost on the picking episodes, over every exported pick."""
    gaps, over = [], 0
    for final_path in sorted(RESULTS.rglob("final_eval.json")):
        picked = json.loads(final_path.read_text())["delivered"]
        limit = json.loads((final_path.parent / "config.json").read_text())["task"]["cost_limit"]
        (candidate,) = [c for c in picked["candidates"] if c["epoch"] == picked["epoch"]]
        gaps.append(picked["cost_mean"] - candidate["cost"])
        over += picked["cost_mean"] > limit
    gaps.sort()
    middle = len(gaps) // 2
    median = gaps[middle] if len(gaps) % 2 else (gaps[middle - 1] + gaps[middle]) / 2
    line = (f"The picks' reported cost minus their cost on the picking episodes, over {len(gaps)} "
            f"picks: median {median:+.1f}, mean {sum(gaps) / len(gaps):+.1f}, largest "
            f"{gaps[-1]:+.1f}; {over} of them over the limit on the reported episodes.")
    assert line in (ROOT / "research" / "delivered_policy" / "selection.md").read_text()


def test_the_notes_critic_table_is_the_runs_metrics():
    """research/2026-11-28-delivered-policy.md's SafetyPointGoal1 critic table: each cell the mean
    of metrics.csv's column over the epochs of its window."""
    note = (ROOT / "research" / "2026-11-28-delivered-policy.md").read_text()
    windows = {"100-300k": (100_000, 300_000), "800k-1M": (800_000, 1_000_000)}
    for candidate in ("goal_mean", "goal_bound", "goal_split"):
        path = RESULTS / candidate / "sac_lag_SafetyPointGoal1-v0" / "seed1" / "metrics.csv"
        with path.open() as f:
            metrics = list(csv.DictReader(f))
        for label, (low, high) in windows.items():
            rows = [r for r in metrics if low < float(r["frames"]) <= high]
            assert len(rows) == 20

            def mean(column, rows=rows):
                return f"{sum(float(r[column]) for r in rows) / len(rows):.2f}"

            row = (
                f"| `{candidate}` | {label} | {mean('critic/reward_q')} / "
                f"{mean('critic/reward_return')} | {mean('critic/cost_q')} / "
                f"{mean('critic/cost_return')} | {mean('lagrangian')} |"
            )
            if candidate == "goal_split":  # its table adds the training reward and cost
                row += (f" {float(mean('train/reward')):.1f} / "
                        f"{float(mean('train/cost')):.1f} |")
            assert row in note


def test_a_finished_run_is_exported_once_and_then_skipped(tmp_path, monkeypatch):
    """The queue copies a finished run's result files (not its checkpoints) into --export, and on
    a machine without the run (checkpoints gone) skips it because the copy is there."""
    module = _script("selection")
    out, export = tmp_path / "runs", tmp_path / "exported"
    source = ROOT / "results" / "table1" / "s3rl_SafetyAntRun-v0" / "seed10"
    job = next(module.jobs(out))
    run_dir = job[0]
    run_dir.mkdir(parents=True)
    for name in ("config.json", "metrics.csv", "final_eval.json"):
        (run_dir / name).write_bytes((source / name).read_bytes())
    (run_dir / "checkpoints" / "latest").mkdir(parents=True)
    (run_dir / "checkpoints" / "latest" / "state.pt").write_bytes(b"not exported")
    monkeypatch.setattr(module.subprocess, "call", lambda *a, **k: pytest.fail("trained"))

    assert module.run(job, out, export).startswith("done already")
    copy = export / run_dir.relative_to(out)
    assert sorted(p.name for p in copy.iterdir()) == [
        "config.json", "final_eval.json", "metrics.csv"]
    assert (copy / "metrics.csv").read_bytes() == (source / "metrics.csv").read_bytes()

    for path in sorted(run_dir.rglob("*"), reverse=True):  # another machine: no run directory
        path.unlink() if path.is_file() else path.rmdir()
    assert module.run(job, out, export) == f"exported already: {copy}"


def test_the_evidence_queue_runs_the_shipped_sweeps_jobs_in_its_directories(tmp_path):
    """evidence.py's first jobs are configs/sweep/table1_v2.yaml's first jobs (the first
    parameter varies slowest, as Hydra launches them), each in the sweep's subdir under --out."""
    # Closed after four jobs: the generator holds Hydra's global config directory until then.
    with contextlib.closing(_script("evidence").jobs(tmp_path)) as queue:
        first = [next(queue) for _ in range(4)]
    expected = [("s3rl", 10), ("s3rl", 20), ("s3rl", 30), ("sac_lag", 10)]
    for (run_dir, overrides), (algo, seed) in zip(first, expected, strict=True):
        assert run_dir == tmp_path / f"{algo}_SafetyCarCircle-v0" / f"seed{seed}"
        assert overrides[:4] == ["experiment=safe", "task=SafetyCarCircle-v0", f"algo={algo}",
                                 f"seed={seed}"]
        assert {"resume=auto", "threads=1"} <= set(overrides)
        assert overrides[-1] == f"hydra.run.dir={run_dir}"
    # The reproduction (issue 63) through the same queue: experiment=paper, its first task.
    with contextlib.closing(_script("evidence").jobs(tmp_path, "reproduction")) as queue:
        run_dir, overrides = next(queue)
    assert run_dir == tmp_path / "s3rl_SafetyAntVelocity-v1" / "seed10"
    assert overrides[:4] == ["experiment=paper", "task=SafetyAntVelocity-v1", "algo=s3rl",
                             "seed=10"]


def test_the_preset_is_the_rules_choice():
    """experiment=safe carries what the last line of selection.md chose: the candidate's
    overrides (selection.py) and, for the delivered pick, the queue's delivery settings."""
    from s3rl_torchrl.trainer import validate
    from tests.conftest import compose_train

    last_line = (ROOT / "research" / "delivered_policy" / "selection.md").read_text().splitlines()[-1]
    assert last_line.startswith("The rule's choice: margin, delivered pick (14 of 14")
    composed = compose_train("experiment=safe", "algo=s3rl")
    selection = _script("selection")
    for override in (*selection.CANDIDATES["margin"], *selection.DELIVERY):
        key, value = override.split("=")
        assert str(OmegaConf.select(composed, key)) == value, override
    assert validate(composed).algo.lagrangian_eval_window == 0  # aim's window is not part of it


def test_the_goal_budget_keeps_lambdas_rate_per_frame(tmp_path, monkeypatch):
    """goal_budget's run (retired after SAC-Lag seed 1) composes and validates, with 5x the
    gradient steps per frame and lambda's rate per update cut by as much (lambda updates once
    per gradient step under experiment=safe); the queue holds no retired SafetyPointGoal1
    candidate's runs, and an open one's four at 1M frames, last; each candidate composes to what
    its note says, and `--runs` queues only the runs its glob names."""
    from s3rl_torchrl.trainer import validate
    from tests.conftest import compose_train

    selection = _script("selection")
    assert selection.GOAL_CANDIDATES == {}
    assert set(selection.RETIRED_GOAL_CANDIDATES) == {
        "goal_mean", "goal_bound", "goal_split", "goal_budget", "goal_horizon20", "goal_horizon10",
        "goal_buffer", "goal_buffer_split", "goal_buffer_budget"}
    task = ["task=SafetyPointGoal1-v0", "algo=sac_lag", "seed=1", "collector.total_frames=1000000"]
    preset = validate(compose_train("experiment=safe", *task))
    budget = validate(compose_train(
        "experiment=safe", *task, *selection.RETIRED_GOAL_CANDIDATES["goal_budget"]))
    assert budget.algo.lagrangian_cadence == preset.algo.lagrangian_cadence == "step"
    assert budget.algo.update_per_step == 5 * preset.algo.update_per_step == 1.0
    assert budget.algo.lagrangian_lr * budget.algo.update_per_step == pytest.approx(
        preset.algo.lagrangian_lr * preset.algo.update_per_step)
    jobs = list(selection.jobs(tmp_path))
    assert not [run_dir for run_dir, _ in jobs if "SafetyPointGoal1" in str(run_dir)]
    # An open candidate (the CASES hold the dict itself) queues four runs, SAC-Lag seed 1 first,
    # after every margin/aim run.
    monkeypatch.setitem(selection.GOAL_CANDIDATES, "goal_open", ["algo.gamma=0.98"])
    opened = list(selection.jobs(tmp_path))
    goal = {run_dir.relative_to(tmp_path).as_posix(): overrides
            for run_dir, overrides in opened if "SafetyPointGoal1" in str(run_dir)}
    assert list(goal) == [f"goal_open/{algo}_SafetyPointGoal1-v0/seed{seed}"
                          for seed in (1, 2) for algo in ("sac_lag", "s3rl")]
    assert [run_dir for run_dir, _ in opened][-4:] == [tmp_path / name for name in goal]
    assert all("collector.total_frames=1000000" in overrides and "algo.gamma=0.98" in overrides
               for overrides in goal.values())
    eleventh = validate(compose_train(
        "experiment=safe", *task, *selection.RETIRED_GOAL_CANDIDATES["goal_buffer_budget"]))
    assert (eleventh.algo.buffer_size, eleventh.algo.cost_target_read, eleventh.algo.update_per_step,
            eleventh.algo.lagrangian_lr) == (1_000_000, "mean", 1.0, budget.algo.lagrangian_lr)
    retired = selection.RETIRED_GOAL_CANDIDATES
    for name, gamma, buffer in (("goal_horizon20", 0.95, 100_000),
                                ("goal_horizon10", 0.9, 100_000), ("goal_buffer", 0.99, 1_000_000)):
        composed = validate(compose_train(
            "experiment=safe", *task, *selection.GOAL_CANDIDATES.get(name, retired.get(name))))
        assert (composed.algo.gamma, composed.algo.buffer_size) == (gamma, buffer)
        assert (preset.algo.gamma, preset.algo.buffer_size) == (0.99, 100_000)
        assert composed.algo.lagrangian_lr == preset.algo.lagrangian_lr  # the task's settings
        assert composed.task.cost_limit == 25.0
    both = validate(compose_train(
        "experiment=safe", *task, *retired["goal_buffer_split"]))
    assert (both.algo.buffer_size, both.algo.cost_target_read, both.algo.cost_critic_read) == (
        1_000_000, "mean", preset.algo.cost_critic_read)
    assert preset.algo.cost_target_read is None and preset.algo.cost_critic_read == "max"
    picked = [run_dir for run_dir, _ in jobs
              if selection.selected((run_dir, []), tmp_path, "margin/sac_lag_*/seed1")]
    assert picked == [tmp_path / "margin" / f"sac_lag_{task}" / "seed1"
                      for task in ("SafetyPointCircle1-v0", "SafetySwimmerVelocity-v1",
                                   "SafetyBallRun-v0")]
    assert len(jobs) == 2 * 2 * 7  # margin/aim on seven cases
    assert len(opened) == 2 * 2 * 7 + 4


def test_goal_windows_count_the_three_epoch_windows_on_target_by_hand():
    target_windows = _script("goal_windows").target_windows
    # Epochs at 100k (the warm-up's last, left out), then five: windows (110-130k), (120-140k),
    # (130-150k) have mean rewards 20, 22, 18 and mean costs 20, 30, 20.
    frames = [100_000, 110_000, 120_000, 130_000, 140_000, 150_000]
    reward = [99.0, 18.0, 21.0, 21.0, 24.0, 9.0]
    cost = [0.0, 0.0, 30.0, 30.0, 30.0, 0.0]
    assert target_windows(frames, reward, cost, 25.0) == (3, 1, 20.0, 130_000)
    assert target_windows(frames, reward, cost, 35.0) == (3, 2, 22.0, 140_000)
    # No window within the limit: no best; fewer epochs than a window: no window.
    windows, hits, best, at = target_windows(frames, reward, [40.0] * 6, 25.0)
    assert (windows, hits, at) == (3, 0, None) and best != best
    assert target_windows(frames[:3], reward[:3], cost[:3], 25.0)[:2] == (0, 0)


def test_goal_windows_read_the_committed_goal_runs():
    module = _script("goal_windows")
    rows = {row[0]: row for row in module.rows([RESULTS])}
    # goal_buffer_split's SAC-Lag seed 1 (its metrics.csv): 88 windows past 100k frames.
    row = rows["delivered_selection/goal_buffer_split/sac_lag_SafetyPointGoal1-v0/seed1"]
    assert row[1:4] == ["1000k", "88", "3"] and row[4] == "25.7 (340k)"
    assert all(name.split("/")[2].startswith("sac_lag_SafetyPointGoal1") for name in rows)


def test_goal_windows_span_means_by_hand_and_on_the_3m_runs():
    module = _script("goal_windows")
    frames = [100_000, 200_000, 300_000, 400_000]
    values = [1.0, 2.0, 4.0, 9.0]
    assert module.span_means(frames, values, 100_000, 300_000) == 3.0  # (2 + 4) / 2: low excluded
    assert module.span_means(frames, values, 300_000, 500_000) is None  # the run stops at 400k
    assert module.parse_spans("0.8-1,2.5-3") == [(800_000, 1_000_000), (2_500_000, 3_000_000)]
    with pytest.raises(SystemExit, match="not <low>-<high>"):
        module.parse_spans("1-x")
    rows = module.span_rows([RESULTS.parent / "goal_3m"], module.parse_spans("2.5-3,2.5-3.5"))
    # the note's last goal_buffer_split row; no row for a span past the runs' 3M frames
    assert ["goal_3m/goal_buffer_split/sac_lag_SafetyPointGoal1-v0/seed1", "2.5-3M", "15.3 / 10.1",
            "17.0 / 15.1", "0.56", "0.64 / 1.68", "1.19 / 1.62"] in rows
    assert {row[1] for row in rows} == {"2.5-3M"}


def test_goal_held_by_hand():
    goal_held = _script("goal_windows").goal_held
    # Lambda is off for the first epoch; the trailing 3-epoch mean evaluation reward is
    # (nan, nan, 20, 16, 12, 9): the goal is held at 30k and 40k, last at 40k (lambda 0.2).
    frames = [10_000, 20_000, 30_000, 40_000, 50_000, 60_000]
    lam = [0.0, 0.1, 0.1, 0.2, 0.3, 0.4]
    eval_reward = [24.0, 21.0, 15.0, 12.0, 9.0, 6.0]
    train_reward = [25.0, 22.0, 19.0, 20.0, 5.0, 1.0]
    train_cost = [90.0, 40.0, 30.0, 20.0, 10.0, 0.0]
    # Training cost over the lambda > 0 epochs up to 40k: (40 + 30 + 20) / 3; the lowest of
    # those with a training reward >= 20: 20 (at 40k; 90 at 10k had lambda off).
    assert goal_held(frames, lam, eval_reward, train_reward, train_cost) == (40_000, 0.2, 30.0,
                                                                             20.0)
    # Never held while lambda was on: None; held without a rewarded epoch: nan.
    assert goal_held(frames, [0.0] * 6, eval_reward, train_reward, train_cost) is None
    held = goal_held(frames, lam, eval_reward, [0.0] * 6, train_cost)
    assert held[:3] == (40_000, 0.2, 30.0) and held[3] != held[3]


def test_goal_held_gives_the_notes_columns():
    """research/2026-12-07-pointgoal1-horizon.md's "goal held until" and "training cost while
    held" cells, from the exported runs."""
    rows = {row[0].split("/")[1]: row[2:] for row in _script("goal_windows").held_rows([RESULTS])}
    note = (ROOT / "research" / "2026-12-07-pointgoal1-horizon.md").read_text()
    for candidate in ("goal_horizon20", "goal_horizon10", "goal_buffer", "goal_buffer_split",
                      "goal_buffer_budget"):
        held, cost = rows[candidate]
        assert f"| `{candidate}` | sac_lag seed 1 | 1000k | {held} | {cost} |" in note
