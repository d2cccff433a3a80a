"""report.md and its figures: synthetic runs (numbers chosen here), the CLI, and real tiny runs
(checkpoint rollouts for Figure 4, the training-time probe column)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from scipy import stats

from s3rl_torchrl.report.build import build_report
from s3rl_torchrl.report.cli import main
from s3rl_torchrl.report.runs import read_run
from s3rl_torchrl.trainer import register_configs, train, validate

CONFIG_DIR = str(Path(__file__).resolve().parents[2] / "configs")
TASK = "SafetyHalfCheetahVelocity-v1"


def _non_empty(path: Path) -> bool:
    return path.is_file() and path.stat().st_size > 0


def _sweep(tmp_path, make_run) -> dict:
    """Two algos x three seeds; seed 4 of s3rl unfinished. sac_lag's cost exceeds the limit."""
    costs = {"s3rl": [0.0, 2.0, 1.0, 3.0], "sac_lag": [12.0, 15.0, 11.0, 14.0]}
    rewards = {}
    for algo in ("s3rl", "sac_lag"):
        for seed in (1, 2, 3):
            r = [100.0 + 10 * seed + i + (4 + seed if algo == "s3rl" else 0) for i in range(4)]
            rewards[algo, seed] = r
            episodes = {"rewards": r, "costs": costs[algo], "lengths": [50] * 4,
                        "safe_steps": [50, 48, 49, 47] if algo == "s3rl" else [40] * 4}
            make_run(tmp_path / "sweep" / f"{algo}_seed{seed}", TASK, algo, seed, episodes)
    make_run(tmp_path / "sweep" / "s3rl_seed4", TASK, "s3rl", 4, finished=False)
    return rewards


def test_report_on_synthetic_runs(tmp_path, make_run):
    rewards = _sweep(tmp_path, make_run)
    report = build_report(tmp_path / "sweep", tmp_path / "report")
    text = report.path.read_text()

    # Table 1 rows, by hand: s3rl per-seed means 116.5, 127.5, 138.5; pooled over 12 episodes.
    s3rl_pooled = np.concatenate([rewards["s3rl", s] for s in (1, 2, 3)])
    seed_means = [np.mean(rewards["s3rl", s]) for s in (1, 2, 3)]
    row = next(line for line in text.splitlines() if line.startswith(f"| {TASK} | s3rl | 3 |"))
    assert f"{np.mean(seed_means):.2f} ± {np.std(seed_means, ddof=1):.2f}" in row
    assert f"{s3rl_pooled.mean():.2f} ± {s3rl_pooled.std():.2f}" in row
    assert "⚠" not in row  # cost 1.5 < 10
    lag = next(line for line in text.splitlines() if line.startswith(f"| {TASK} | sac_lag |"))
    assert "13.00 ± 0.00 ⚠" in lag  # every seed's mean cost is 13 > 10

    # The unfinished run: listed, out of the table (3 seeds), in the curves.
    assert "## Unfinished runs" in text and "s3rl seed 4, 400 of 600 frames" in text

    # Differences: Welch over the pooled episodes as scipy computes it.
    lag_pooled = np.concatenate([rewards["sac_lag", s] for s in (1, 2, 3)])
    welch = stats.ttest_ind(s3rl_pooled, lag_pooled, equal_var=False)
    ci = welch.confidence_interval(0.95)
    diff_row = next(line for line in text.splitlines() if "| reward | s3rl − sac_lag |" in line)
    assert f"p = {welch.pvalue:.2g}, CI [{ci.low:.2f}, {ci.high:.2f}] (12 vs 12 episodes" in (
        diff_row
    )
    # Each seed's 4 episodes are 0, 1, 2, 3 above its base (variance 1.25) while sac_lag's
    # seeds are 10 apart (variance of the seed means 200 / 3): the within-seed share of its
    # pooled variance is under 5%, so the Welch cell is flagged.
    assert 1.25 / (1.25 + 200 / 3) < 0.05
    assert "12 vs 12 episodes; episodes of a seed near copies" in diff_row
    # Paired over seeds (differences 5, 6, 7), as scipy computes it.
    paired = stats.ttest_rel(seed_means, [np.mean(rewards["sac_lag", s]) for s in (1, 2, 3)])
    ci = paired.confidence_interval(0.95)
    assert f"| 6.00 | p = {paired.pvalue:.2g}, CI [{ci.low:.2f}, {ci.high:.2f}] (3 pairs) |" in (
        diff_row
    )
    # Every seed has the same costs: the seed-paired cost differences are all -11.5, scipy
    # says t = -inf, p = 0, and the table flags it.
    cost_row = next(line for line in text.splitlines() if "| cost | s3rl − sac_lag |" in line)
    assert "| -11.50 | p < 1e-4, CI [-11.50, -11.50] (3 pairs; no variance) |" in cost_row

    # The paper's Table 1 numbers for this task (our v1 id = the paper's Gymnasium-API id).
    assert "| Table 1 (S3RL, Lag) |" in text and "2828.95 ± 50.71" in text
    # Beyond the paper's spread: reward 127.5 against 2828.95 ± 50.71 is; cost 1.5 against
    # 1.70 ± 4.43 is not. SAC-Lag's cost 13 against 0.30 ± 1.33 is too.
    paper_row = next(line for line in text.splitlines()
                     if line.startswith(f"| {TASK} | s3rl | Table 1 (S3RL, Lag) |"))
    assert paper_row.endswith("| reward | last policy |")
    paper_row = next(line for line in text.splitlines()
                     if line.startswith(f"| {TASK} | sac_lag | Table 1 (SAC-LAG, Lag) |"))
    assert paper_row.endswith("| reward, cost | last policy |")
    # Figure 3's difference in percentage points: (194 - 160) / 200 * 100 = 17.0
    # (the paper quotes no Figure 3 difference for HalfCheetah: last column empty)
    assert f"| {TASK} | sac_lag | 80.0 ± 0.0 | +17.0 |  |" in text

    names = {p.name for p in report.figures}
    for stem in ("figure2_learning_curves", "figure3_safe_occupancy"):
        assert {f"{stem}.png", f"{stem}.svg"} <= names
        assert _non_empty(tmp_path / "report" / f"{stem}.png")
        assert _non_empty(tmp_path / "report" / f"{stem}.svg")
    # No checkpoints in synthetic runs: Figure 4 is left out with a note, not an error.
    assert any("Figure 4: no finished run" in note for note in report.notes)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "s3rl_torchrl.report.cli", *args],
        capture_output=True, text=True, timeout=300,
    )


def test_cli_errors_and_success(tmp_path, make_run, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main([str(empty)]) == 2
    assert "No runs found below" in capsys.readouterr().err

    make_run(tmp_path / "mixed" / "a", seed=1)
    make_run(tmp_path / "mixed" / "b", seed=2, collector__total_frames=800)
    assert main([str(tmp_path / "mixed")]) == 2
    assert "collector.total_frames: 600" in capsys.readouterr().err

    # The module as a program (what the s3rl-report console script runs).

    out = _cli(str(tmp_path / "mixed"), "--group-by", "collector.total_frames",
               "--out", str(tmp_path / "rep"), "--no-embeddings")
    assert out.returncode == 0, out.stderr
    assert _non_empty(tmp_path / "rep" / "report.md")
    assert "s3rl (collector.total_frames=800)" in (tmp_path / "rep" / "report.md").read_text()


def test_export_runs_copies_the_results_only_and_rebuilds_the_same_table(tmp_path, make_run):
    _sweep(tmp_path, make_run)
    checkpoint = tmp_path / "sweep" / "s3rl_seed1" / "checkpoints" / "latest" / "state.pt"
    checkpoint.parent.mkdir(parents=True)
    checkpoint.write_bytes(b"weights")
    assert main([str(tmp_path / "sweep"), "--export-runs", str(tmp_path / "kept"),
                 "--no-embeddings"]) == 0
    kept = sorted(p.relative_to(tmp_path / "kept").as_posix() for p in (tmp_path / "kept").rglob("*")
                  if p.is_file())
    assert "s3rl_seed1/config.json" in kept and "s3rl_seed1/final_eval.json" in kept
    assert "s3rl_seed4/metrics.csv" in kept and "s3rl_seed4/final_eval.json" not in kept
    assert not any("checkpoints" in p for p in kept) and len(kept) == 3 * 6 + 2
    original = build_report(tmp_path / "sweep", tmp_path / "r1", embeddings=False)
    rebuilt = build_report(tmp_path / "kept", tmp_path / "r2", embeddings=False)
    table = [line for line in original.path.read_text().splitlines() if line.startswith("| ")]
    assert table == [line for line in rebuilt.path.read_text().splitlines()
                     if line.startswith("| ")]
    # Exporting into the runs' own tree would copy runs into themselves.
    assert main([str(tmp_path / "sweep"), "--export-runs", str(tmp_path / "sweep" / "x"),
                 "--no-embeddings"]) == 2


def test_several_roots_make_one_report_that_names_the_paper_tasks_left_out(
    tmp_path, make_run, capsys
):
    """Two results trees (the evidence tasks and the other Table 1 tasks) in one report: the
    tables of both, and the paper's Table 1 tasks that neither has."""
    rewards = _sweep(tmp_path, make_run)  # HalfCheetah, both algos, below sweep/
    for algo in ("s3rl", "sac_lag"):
        for seed in (1, 2):
            make_run(tmp_path / "other" / f"{algo}_seed{seed}", "SafetyBallRun-v0", algo, seed)
    # A task of only one algo is not covered.
    make_run(tmp_path / "other" / "s3rl_ant", "SafetyAntRun-v0", "s3rl", 1)

    text = build_report([tmp_path / "sweep", tmp_path / "other"], tmp_path / "both",
                        embeddings=False, aggregate=False).path.read_text()
    assert f"| {TASK} | s3rl | 3 |" in text and "| SafetyBallRun-v0 | s3rl | 2 |" in text
    assert f"below `{tmp_path / 'sweep'}`, `{tmp_path / 'other'}` (" in text
    coverage = next(line for line in text.splitlines() if line.startswith("The paper's Table 1"))
    assert "has 16 tasks; 2 of them have finished runs of s3rl and another algo here" in coverage
    left_out = coverage.split("Not (yet) here: ")[1].rstrip(".").split(", ")
    assert len(left_out) == 14 and "SafetyAntRun-v0" in left_out
    assert "SafetyBallRun-v0" not in left_out and "SafetyHalfCheetahVelocityGymnasium-v1" not in (
        left_out)

    # Table 1 in full: the paper's 16 tasks x 2 algos, ours beside them where they ran.
    full = text.split("### Table 1 in full")[1].split("\n## ")[0]
    rows = [line for line in full.splitlines() if line.startswith("| Safety")]
    assert len(rows) == 32
    s3rl_pooled = np.mean(np.concatenate([rewards["s3rl", s] for s in (1, 2, 3)]))
    assert (f"| SafetyHalfCheetahVelocityGymnasium-v1 | S3RL | 2828.95 / 1.70 | "
            f"{s3rl_pooled:.2f} / 1.50 (3) | – |") in rows
    # make_run's default episodes: rewards 10 + seed, 12 + seed, 11, 9; costs 0, 2, 1, 3.
    ball = (11 + 13 + 11 + 9 + 12 + 14 + 11 + 9) / 8
    assert f"| SafetyBallRun-v0 | SAC-LAG | -411.08 / 80.02 | {ball:.2f} / 1.50 (2) | – |" in rows
    assert any(r.startswith("| SafetyAntRun-v0 | S3RL |") and r.endswith("/ 1.50 (1) | – |")
               for r in rows)
    assert any(r.startswith("| SafetyAntRun-v0 | SAC-LAG |") and r.endswith("| – | – |")
               for r in rows)

    # The same seed of a group below both roots is reported once or not at all.
    make_run(tmp_path / "again" / "s3rl_seed1", "SafetyBallRun-v0", "s3rl", 1)
    assert main([str(tmp_path / "other"), str(tmp_path / "again"), "--no-embeddings"]) == 2
    assert "Seed 1 of task=SafetyBallRun-v0 algo=s3rl appears twice" in capsys.readouterr().err
    # An export mirrors one tree.
    assert main([str(tmp_path / "sweep"), str(tmp_path / "other"), "--export-runs",
                 str(tmp_path / "kept")]) == 2
    assert "--export-runs copies one RUNS directory" in capsys.readouterr().err
    assert not (tmp_path / "kept").exists()


def test_export_again_removes_what_the_runs_no_longer_have(
    tmp_path, make_run, monkeypatch, capsys
):
    """A re-export mirrors the runs: a final_eval.json of a run that is unfinished now goes,
    and a group keeps one Figure-4 panel (the one drawn now), not an earlier one on another
    seed."""
    from s3rl_torchrl.diagnostics.probe import ProbeResult
    from s3rl_torchrl.report import embeddings

    _sweep(tmp_path, make_run)
    kept = tmp_path / "kept"
    (kept / "s3rl_seed4").mkdir(parents=True)
    (kept / "s3rl_seed4" / "final_eval.json").write_text("{}")  # from an earlier export
    for name in embeddings.PANEL_FILES:  # an earlier panel on seed 1
        (kept / "s3rl_seed1").mkdir(exist_ok=True)
        (kept / "s3rl_seed1" / name).write_text("old")
    # Only seed 2 has a checkpoint now, so its panel is drawn (a fixed one: no rollout here).
    (tmp_path / "sweep" / "s3rl_seed2" / "checkpoints" / "latest").mkdir(parents=True)
    panel = embeddings.EmbeddingPanel(
        xy=np.zeros((4, 2)), safe=np.array([True, False, True, False]),
        probe=ProbeResult(0.75, 0.8, 0.5, 2, 2, 2, 2), episodes=2)
    monkeypatch.setattr(embeddings, "embedding_panel", lambda *a, **k: panel)

    assert main([str(tmp_path / "sweep"), "--export-runs", str(kept)]) == 0
    assert not (kept / "s3rl_seed4" / "final_eval.json").exists()
    assert (kept / "s3rl_seed4" / "metrics.csv").is_file()
    assert not any((kept / "s3rl_seed1" / name).exists() for name in embeddings.PANEL_FILES)
    stored = embeddings.load_panel(kept / "s3rl_seed2")
    np.testing.assert_array_equal(stored.safe, panel.safe)
    assert stored.probe.accuracy == 0.75
    # A run gone from the source loses its copy (a file of the user's beside it stays).
    gone = kept / "s3rl_seed9"
    gone.mkdir()
    for name in ("config.json", "metrics.csv", "final_eval.json"):
        (gone / name).write_text("{}")
    (kept / "s3rl_seed8").mkdir()
    (kept / "s3rl_seed8" / "config.json").write_text("{}")
    (kept / "s3rl_seed8" / "metrics.csv").write_text("frames\n")
    (kept / "s3rl_seed8" / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main([str(tmp_path / "sweep"), "--export-runs", str(kept), "--no-embeddings"]) == 0
    assert not gone.exists() and sorted(p.name for p in (kept / "s3rl_seed8").iterdir()) == [
        "notes.txt"
    ]
    summary = capsys.readouterr().out
    assert "removed 2 run copies no longer in" in summary and "s3rl_seed9" in summary
    assert (kept / "s3rl_seed4" / "metrics.csv").is_file()  # runs still there stay
    # sac_lag has no checkpoint: nothing drawn, nothing removed.
    assert not any((kept / f"sac_lag_seed{s}" / embeddings.PANEL_FILES[0]).exists()
                   for s in (1, 2, 3))


@pytest.fixture(scope="module")
def tiny_runs(tmp_path_factory):
    """S3RL and SAC-Lag, one tiny run each on Swimmer-v1 (it has unsafe states within 600
    frames, HalfCheetah has none)."""
    root = tmp_path_factory.mktemp("tiny")
    register_configs()
    for algo in ("s3rl", "sac_lag"):
        with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
            cfg = compose(config_name="train", overrides=[
                "experiment=tiny", f"algo={algo}", "task=SafetySwimmerVelocity-v1", "seed=3",
                "diagnostics.probes=true",
            ])
        train(validate(cfg), root / algo)
    return root


def test_training_logs_the_probe_every_epoch(tiny_runs):
    run = read_run(tiny_runs / "s3rl")
    frames, accuracy = run.column("probe/accuracy")
    _, auc = run.column("probe/auc")
    assert frames == [200, 400, 600]
    assert all(0.0 <= a <= 1.0 for a in accuracy) and all(0.0 <= u <= 1.0 for u in auc)
    assert not math.isnan(accuracy[-1])


def test_the_probe_does_not_change_training(tiny_runs, tmp_path):
    """The probes draw from their own generators: a run without them trains exactly the same."""
    register_configs()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=[
            "experiment=tiny", "algo=s3rl", "task=SafetySwimmerVelocity-v1", "seed=3",
        ])
    train(validate(cfg), tmp_path / "no_probe")
    with_probe = read_run(tiny_runs / "s3rl").metrics
    without = read_run(tmp_path / "no_probe").metrics
    skip = {"eval/seconds", "probe/accuracy", "probe/auc", "probe/spearman", "probe/r2"}
    for a, b in zip(with_probe, without, strict=True):
        same = {k: a[k] for k in a if k not in skip}
        assert same == pytest.approx({k: b[k] for k in same}, nan_ok=True, rel=0, abs=0)


def test_report_with_checkpoint_rollouts(tiny_runs, tmp_path):
    report = build_report(tiny_runs, tmp_path / "report", embedding_episodes=2, tsne_states=100)
    text = report.path.read_text()
    assert _non_empty(tmp_path / "report" / "figure4_embedding_tsne.png")
    assert _non_empty(tmp_path / "report" / "figure4_embedding_tsne.svg")
    # one probe row per algo: 2 rollouts x eval.max_steps (50) states
    rows = [line for line in text.splitlines() if line.startswith("| SafetySwimmerVelocity-v1 |")
            and "| 3 |" in line]
    assert len(rows) == 2
    for row in rows:
        cells = row.split("|")
        assert cells[4].strip() == "2"  # rollouts
        safe, unsafe = (int(x) for x in cells[5].split("/"))
        assert safe + unsafe == 100


def test_exported_panels_redraw_figure4_without_the_checkpoints(tiny_runs, tmp_path):
    """--export-runs stores each group's panel; the report of the exported tree (no
    checkpoints) gives the probe table of the report drawn from the checkpoints."""
    from s3rl_torchrl.report.embeddings import embedding_panel, load_panel

    kept = tmp_path / "kept"
    assert main([str(tiny_runs), "--export-runs", str(kept), "--tsne-states", "60"]) == 0
    assert not list(kept.rglob("checkpoints"))
    for algo in ("s3rl", "sac_lag"):
        stored = load_panel(kept / algo)
        max_steps = read_run(tiny_runs / algo).config["eval"]["max_steps"]
        fresh = embedding_panel(tiny_runs / algo / "checkpoints" / "latest", max_steps=max_steps,
                                tsne_states=60)
        assert stored.xy.shape == (60, 2) and stored.episodes == 2
        np.testing.assert_allclose(stored.xy, fresh.xy, rtol=1e-5, atol=1e-4)
        np.testing.assert_array_equal(stored.safe, fresh.safe)
        assert astuple(stored.probe) == pytest.approx(astuple(fresh.probe), nan_ok=True, rel=0)

    def probe_rows(report):
        return [line for line in report.path.read_text().splitlines()
                if line.startswith("| SafetySwimmerVelocity-v1 |") and "| 3 |" in line]

    original = build_report(tiny_runs, tmp_path / "r1", tsne_states=60)
    rebuilt = build_report(kept, tmp_path / "r2", tsne_states=60)
    assert len(probe_rows(original)) == 2
    assert probe_rows(rebuilt) == probe_rows(original)
    assert _non_empty(tmp_path / "r2" / "figure4_embedding_tsne.png")
    # A tree with neither checkpoints nor panels: Figure 4 is left out with a note, and the
    # figure an earlier build drew into the same directory goes with it.
    assert main([str(tiny_runs), "--export-runs", str(tmp_path / "bare"), "--no-embeddings"]) == 0
    bare = build_report(tmp_path / "bare", tmp_path / "r2")
    assert "No checkpoint to roll out and no stored panel." in bare.path.read_text()
    assert any("stored panel" in note for note in bare.notes)
    assert not list((tmp_path / "r2").glob("figure4_embedding_tsne.*"))


def test_compare_adds_pairs_beside_the_reference(tmp_path, make_run, capsys):
    rewards = _sweep(tmp_path, make_run)
    assert main([str(tmp_path / "sweep"), "--out", str(tmp_path / "rep"), "--no-embeddings",
                 "--compare", "sac_lag:s3rl", "--compare", "s3rl:sac_lag"]) == 0
    lines = (tmp_path / "rep" / "report.md").read_text().splitlines()
    reverse = next(line for line in lines if "| reward | sac_lag − s3rl |" in line)
    # The reverse pair: minus the reference's difference, same paired test (scipy, by hand).
    paired = stats.ttest_rel([np.mean(rewards["sac_lag", s]) for s in (1, 2, 3)],
                             [np.mean(rewards["s3rl", s]) for s in (1, 2, 3)])
    ci = paired.confidence_interval(0.95)
    assert f"| -6.00 | p = {paired.pvalue:.2g}, CI [{ci.low:.2f}, {ci.high:.2f}] (3 pairs) |" in (
        reverse
    )
    # A pair the reference already covers is not repeated.
    assert sum("| reward | s3rl − sac_lag |" in line for line in lines) == 1
    with pytest.raises(SystemExit):
        main([str(tmp_path / "sweep"), "--compare", "s3rl"])
    assert "expected two algos as A:B" in capsys.readouterr().err


def test_compare_names_groups_split_by_group_by(tmp_path, make_run):
    """Two S3RL variants (one algo, split by --group-by) are compared by their labels."""
    rewards = {}
    for label, shift in (("binary", 0.0), ("cost_to_go", 5.0)):
        for seed in (1, 2, 3):
            r = [100.0 + 10 * seed + i + shift * (seed % 2 + 1) for i in range(4)]
            rewards[label, seed] = r
            episodes = {"rewards": r, "costs": [1.0, 0.0, 2.0, 1.0], "lengths": [50] * 4,
                        "safe_steps": [49, 50, 48, 49]}
            make_run(tmp_path / "sweep" / f"{label}_seed{seed}", TASK, "s3rl", seed, episodes,
                     algo__contrastive_cfg={"label": label})
    graded, binary = (f"s3rl (algo.contrastive_cfg.label={v})" for v in ("cost_to_go", "binary"))
    assert main([str(tmp_path / "sweep"), "--out", str(tmp_path / "rep"), "--no-embeddings",
                 "--group-by", "algo.contrastive_cfg.label",
                 "--compare", f"{graded}:{binary}"]) == 0
    lines = (tmp_path / "rep" / "report.md").read_text().splitlines()
    row = next(line for line in lines if f"| reward | {graded} − {binary} |" in line)
    paired = stats.ttest_rel([np.mean(rewards["cost_to_go", s]) for s in (1, 2, 3)],
                             [np.mean(rewards["binary", s]) for s in (1, 2, 3)])
    ci = paired.confidence_interval(0.95)
    difference = np.mean([np.mean(rewards["cost_to_go", s]) - np.mean(rewards["binary", s])
                          for s in (1, 2, 3)])
    assert f"| {difference:.2f} | p = {paired.pvalue:.2g}, CI [{ci.low:.2f}, {ci.high:.2f}] " \
           "(3 pairs) |" in row
    assert sum(f"{graded} − {binary}" in line for line in lines) == 2  # reward and cost


def test_frame_ticks_are_short_enough_not_to_overlap():
    from s3rl_torchrl.report.figures import _frames_formatter

    label = _frames_formatter()
    assert [label(x, None) for x in (0, 500, 25_000, 125_000, 1_000_000, 2_500_000)] == [
        "0", "500", "25k", "125k", "1M", "2.5M",
    ]


def test_best_feasible_protocol_is_a_labelled_row_beside_the_last_policy(tmp_path, make_run):
    """Runs that kept a best-feasible checkpoint (FSRL's rule) get a second Table 1 row, paper
    comparison row and difference row, read from final_eval.json's ``best_feasible`` entry;
    runs written before it (no entry) get the last-policy row only."""
    best_rewards = {}
    for algo in ("s3rl", "sac_lag"):
        for seed in (1, 2, 3):
            best = {"rewards": [200.0 + 10 * seed + (5 if algo == "s3rl" else 0)] * 2,
                    "costs": [4.0, 6.0], "lengths": [50, 50], "safe_steps": [45, 45]}
            best_rewards[algo, seed] = best["rewards"]
            make_run(tmp_path / "runs" / f"{algo}_seed{seed}", TASK, algo, seed,
                     best_feasible=best)
    make_run(tmp_path / "old" / "s3rl_seed1", TASK, "s3rl", 1)
    text = build_report(tmp_path / "runs", tmp_path / "report").path.read_text()

    last_label, best_label = "last policy", "best-feasible checkpoint (FSRL's rule)"
    table1 = [line for line in text.splitlines() if line.startswith(f"| {TASK} | s3rl | 3 |")]
    assert [row.rstrip(" |").rsplit("| ", 1)[1] for row in table1] == [last_label, best_label]
    # By hand: s3rl's best-feasible seeds score 215, 225, 235 (std 10), each seed's cost 5.
    assert "| 225.00 ± 10.00 |" in table1[1] and "| 5.00 ± 0.00 |" in table1[1]
    # write_run's default episodes (10 + seed, 12 + seed, 11, 9): seed means 10.5 + seed / 2.
    assert "| 11.50 ± 0.50 |" in table1[0]

    best_diff = next(line for line in text.splitlines()
                     if "| reward | s3rl − sac_lag |" in line and best_label in line)
    assert "| 5.00 |" in best_diff  # every seed's pair differs by 5
    paper_rows = [line for line in text.splitlines() if "| Table 1 (S3RL, Lag) |" in line]
    assert {row.rstrip(" |").rsplit("| ", 1)[1] for row in paper_rows} == {last_label, best_label}

    old = build_report(tmp_path / "old", tmp_path / "old_report").path.read_text()
    assert best_label not in "\n".join(
        line for line in old.splitlines() if line.startswith(f"| {TASK} |")
    )


def test_graded_probe_table_names_the_trained_and_the_probed_label(tmp_path, make_run):
    # Last logged values per seed (the NaN of epoch 1 skipped): Spearman 0.5, 0.7, R^2 0.2, 0.4.
    for seed, (rho, r2) in {1: (0.5, 0.2), 2: (0.7, 0.4)}.items():
        curve = {"frames": [200, 400, 600], "eval/reward": [1.0, 2.0, 3.0],
                 "eval/cost": [0.0, 0.0, 0.0], "probe/spearman": [float("nan"), 0.1, rho],
                 "probe/r2": [float("nan"), 0.0, r2]}
        make_run(tmp_path / "graded" / f"s3rl_seed{seed}", TASK, "s3rl", seed, curve=curve,
                 algo__contrastive_cfg={"label": "margin"})
    text = build_report(tmp_path / "graded", tmp_path / "rep", embeddings=False).path.read_text()
    assert "## The graded probe (training)" in text
    row = next(line for line in text.splitlines() if line.startswith(f"| {TASK} | s3rl | margin"))
    assert row == f"| {TASK} | s3rl | margin | margin | 2 | 0.60 ± 0.14 | 0.30 ± 0.14 |"

    # Binary S3RL and an algo without the contrastive phase are probed on the cost-to-go.
    curve = {"frames": [200], "eval/reward": [1.0], "eval/cost": [0.0],
             "probe/spearman": [0.25], "probe/r2": [0.5]}
    make_run(tmp_path / "binary" / "s3rl_seed1", TASK, "s3rl", 1, curve=curve)
    make_run(tmp_path / "binary" / "sac_lag_seed1", TASK, "sac_lag", 1, curve=curve)
    lines = build_report(tmp_path / "binary", tmp_path / "rep2",
                         embeddings=False).path.read_text().splitlines()
    assert f"| {TASK} | s3rl | binary | cost_to_go | 1 | 0.25 | 0.50 |" in lines
    assert f"| {TASK} | sac_lag | none | cost_to_go | 1 | 0.25 | 0.50 |" in lines

    # Runs that logged no graded probe (before every run did): no table.
    make_run(tmp_path / "old" / "s3rl_seed1", TASK, "s3rl", 1)
    old = build_report(tmp_path / "old", tmp_path / "rep3", embeddings=False)
    assert "graded probe" not in old.path.read_text()


def test_critic_diagnostics_table_and_figure_by_hand(tmp_path, make_run, monkeypatch):
    # A run with the critic diagnostics and one from before them (train/cost_q only).
    new = {
        "frames": [200, 400, 600, 800, 1000],
        "eval/reward": [1.0, 2.0, 3.0, 4.0, 5.0], "eval/cost": [5.0] * 5,
        "train/alpha": [0.01, 0.02, 0.5, 0.04, 0.03],
        "train/cost_q": [1.0, 2.0, 3.0, 4.0, 5.0],
        "critic/cost_q": [-1.0, 2.0, -3.0, 4.0, 6.0],
        "critic/cost_return": [1.0, 1.0, 1.0, 1.0, 2.0],
        "critic/cost_error": [-2.0, 1.0, -4.0, 3.0, 4.0],
        "grad/reward": [1.0] * 5, "grad/entropy": [1.0] * 5, "grad/cost": [0.0, 1.0, 2.0, 2.0, 6.0],
    }
    old = {"frames": [200, 400, 600, 800, 1000], "eval/reward": [1.0] * 5, "eval/cost": [5.0] * 5,
           "train/alpha": [0.01, 7.0, 70.0, 700.0, 7000.0],
           "train/cost_q": [-1.0, -2.0, 3.0, -4.0, -5.0], "train/reward_q": [9.0] * 5}
    make_run(tmp_path / "runs" / "new", TASK, "sac_lag", 1, curve=new)
    make_run(tmp_path / "runs" / "old", TASK, "s3rl", 1, curve=old)
    from s3rl_torchrl.report import figures

    drawn = {}
    real_save = figures._save

    def keep(fig, out_dir, name):
        if name == "critic_diagnostics":
            drawn["axes"] = fig.axes
            drawn["lines"] = [[(line.get_label(), line.get_linestyle(), list(line.get_ydata()))
                               for line in ax.get_lines()] for ax in fig.axes]
        return real_save(fig, out_dir, name)

    monkeypatch.setattr(figures, "_save", keep)
    report = build_report(tmp_path / "runs", tmp_path / "report", embeddings=False)
    text = report.path.read_text()
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
             if line.startswith(f"| {TASK} |")]
    rows = {c[1]: c[2:] for c in cells if len(c) == 6 and c[2].endswith("%")}
    # new: 2 of 5 critic/cost_q below 0; error over the last 20% (1 epoch): 4.0; alpha max 0.5;
    # cost share of the last epoch: 6 / (1 + 1 + 6).
    assert rows["sac_lag"] == ["40%", "4.00", "0.5", "0.75"]
    # old: train/cost_q below 0 in 4 of 5 epochs; no calibration or gradient columns.
    assert rows["s3rl"] == ["80%", "-", "7e+03", "-"]
    assert (tmp_path / "report" / "critic_diagnostics.png").stat().st_size > 0
    # The cost critic's panel (first axis, the only task): the new run's critic solid and the
    # return dashed; the old run's train/cost_q dotted.
    styles = {(label, style): ydata for label, style, ydata in drawn["lines"][0]}
    assert styles[("sac_lag (1 seeds)", "-")] == new["critic/cost_q"]
    assert [y for (label, s), y in styles.items() if s == "--"] == [new["critic/cost_return"]]
    assert styles[("s3rl (1 seeds)", ":")] == old["train/cost_q"]


def test_delivered_protocol_adds_its_rows_and_column_only_where_runs_have_it(tmp_path, make_run):
    """eval.delivery_epochs' pick (final_eval.json's ``delivered``) is read as a third protocol:
    a Table 1 row of its own and a column of "Table 1 in full"; reports of runs without it keep
    their two columns."""
    for algo in ("s3rl", "sac_lag"):
        for seed in (1, 2):
            run = make_run(tmp_path / "runs" / f"{algo}_seed{seed}", TASK, algo, seed)
            final = json.loads((run / "final_eval.json").read_text())
            final["delivered"] = {**final, "reward_mean": 100.0 + seed, "episode_rewards":
                                  [100.0 + seed] * 4, "epoch": 3, "frames": 600}
            (run / "final_eval.json").write_text(json.dumps(final))
    text = build_report(tmp_path / "runs", tmp_path / "report", embeddings=False,
                        aggregate=False).path.read_text()
    label = "delivered policy (picked among the last epochs')"
    table1 = [line for line in text.splitlines() if line.startswith(f"| {TASK} | s3rl | 2 |")]
    assert table1[-1].rstrip(" |").endswith(label) and "| 101.50 ± 0.71 |" in table1[-1]
    full = text.split("### Table 1 in full")[1].split("\n## ")[0]
    assert f"ours, {label}: reward / cost (seeds)" in full
    assert "| 101.50 / 1.50 (2) |" in full
    old = build_report(tmp_path / "runs" / "s3rl_seed1", tmp_path / "old", embeddings=False,
                       aggregate=False).path.read_text()
    assert label in old  # the one run has it too; a run without it:
    make_run(tmp_path / "plain" / "s3rl_seed1", TASK, "s3rl", 1)
    plain = build_report(tmp_path / "plain", tmp_path / "plain_report", embeddings=False,
                         aggregate=False).path.read_text()
    assert label not in plain


def test_the_report_silences_mujocos_settotalmass_warning(tmp_path):
    # The embedding panels build each task's envs; MuJoCo warned of half_cheetah.xml's
    # deprecated settotalmass once per env built (six times in one report). A process of its
    # own: the filter is MuJoCo's handler, set once per process.
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(
        f"""
        from s3rl_torchrl.report import cli
        try:
            cli.main([{str(tmp_path / "no_runs")!r}, "--out", {str(tmp_path / "out")!r}])
        except BaseException:
            pass  # no runs to report: the report's set-up is what is checked
        from s3rl_torchrl.envs import make_env
        make_env("SafetyHalfCheetahVelocity-v1", num_envs=1, seed=0).reset()
        print("built")
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "built" in done.stdout, done.stderr
    assert "settotalmass" not in done.stdout + done.stderr
