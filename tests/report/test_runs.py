"""Finding and grouping run directories; clear errors for what cannot be reported."""

from __future__ import annotations

import json
import math

import pytest

from s3rl_torchrl.report.runs import ReportError, config_differences, find_runs, group_runs


def test_empty_directory_is_an_error(tmp_path):
    (tmp_path / "not_a_run").mkdir()
    (tmp_path / "not_a_run" / "config.json").write_text("{}")  # no metrics.csv
    with pytest.raises(ReportError, match="No runs found below"):
        find_runs(tmp_path)
    with pytest.raises(ReportError, match="is not a directory"):
        find_runs(tmp_path / "missing")


def test_single_run_multirun_and_nested_outputs(tmp_path, make_run):
    single = make_run(tmp_path / "single", seed=5)
    assert [r.path for r in find_runs(single)] == [single]
    # outputs/<algo>/<task>/seed<k>/<time> and multirun/<time>/<job> layouts, one tree
    make_run(tmp_path / "outputs" / "s3rl" / "T" / "seed1" / "2026-01-01_00-00-00", seed=1)
    make_run(tmp_path / "multirun" / "2026" / "sac_lag_T_seed2", algo="sac_lag", seed=2)
    runs = find_runs(tmp_path)
    assert len(runs) == 3
    groups = group_runs(runs)
    assert [(g.task, g.algo, [r.seed for r in g.runs]) for g in groups] == [
        ("SafetyHalfCheetahVelocity-v1", "s3rl", [1, 5]),
        ("SafetyHalfCheetahVelocity-v1", "sac_lag", [2]),
    ]


def test_duplicate_seed_is_an_error(tmp_path, make_run):
    make_run(tmp_path / "a", seed=1)
    make_run(tmp_path / "b", seed=1)
    with pytest.raises(ReportError, match="Seed 1 of task=.* appears twice"):
        group_runs(find_runs(tmp_path))


def test_mixed_configs_are_refused_with_the_differing_keys(tmp_path, make_run):
    make_run(tmp_path / "a", seed=1)
    make_run(tmp_path / "b", seed=2, algo__pid__kp=0.5)
    make_run(tmp_path / "c", seed=3, threads=2, logger__backend="wandb")  # run-specific: fine
    runs = find_runs(tmp_path)
    with pytest.raises(ReportError, match=r"differ in more than the seed") as err:
        group_runs(runs)
    message = str(err.value)
    assert "algo.pid.kp" in message and "--group-by algo.pid.kp" in message
    assert "threads" not in message and "logger" not in message
    groups = group_runs(runs, group_by=["algo.pid.kp"])
    assert [(g.label, [r.seed for r in g.runs]) for g in groups] == [
        ("s3rl (algo.pid.kp=0.05)", [1, 3]),
        ("s3rl (algo.pid.kp=0.5)", [2]),
    ]
    with pytest.raises(ReportError, match="no such config key"):
        group_runs(runs, group_by=["algo.nope"])


def test_configs_are_compared_as_each_run_ran(tmp_path, make_run):
    # A run saved before algo.cost_target_read existed, holding fields its family never read
    # and a removed option at its default, ran as one saved with the option unset.
    old = make_run(tmp_path / "old", seed=1, algo__ppo_epochs=10, algo__cost_gamma=None)
    new = make_run(tmp_path / "new", seed=2, algo__cost_target_read=None)
    changed = make_run(tmp_path / "changed", seed=3, algo__cost_target_read="mean")
    config = json.loads((old / "config.json").read_text())
    config["resumes"] = [{"frames": 200, "changed": {}, "exact": True}]
    (old / "config.json").write_text(json.dumps(config))

    runs = {r.seed: r for r in find_runs(tmp_path)}
    assert "algo.cost_target_read" not in runs[1].config["algo"]
    assert runs[1].settings["algo.cost_target_read"] is None
    assert "algo.ppo_epochs" not in runs[1].settings
    assert config_differences([runs[1], runs[2]]) == {}
    assert config_differences([runs[1], runs[3]]) == {"algo.cost_target_read": [None, "mean"]}
    groups = group_runs(list(runs.values()), group_by=["algo.cost_target_read"])
    assert sorted((g.label, sorted(r.seed for r in g.runs)) for g in groups) == [
        ("s3rl (algo.cost_target_read=None)", [1, 2]),
        ("s3rl (algo.cost_target_read=mean)", [3]),
    ]
    assert {old, new, changed} == {r.path for r in runs.values()}


def test_a_config_this_version_cannot_read_is_compared_as_written(tmp_path, make_run):
    make_run(tmp_path / "a", seed=1, algo__cost_gamma=0.9)  # removed at another value
    make_run(tmp_path / "b", seed=2)
    runs = {r.seed: r for r in find_runs(tmp_path)}
    assert runs[1].settings["algo.cost_gamma"] == 0.9
    with pytest.raises(ReportError, match=r"algo.cost_gamma: 0.9 .*'<missing>'"):
        group_runs(list(runs.values()))


def test_unfinished_runs_are_kept_and_marked(tmp_path, make_run):
    make_run(tmp_path / "done", seed=1)
    make_run(tmp_path / "running", seed=2, finished=False)
    (group,) = group_runs(find_runs(tmp_path))
    assert [r.seed for r in group.finished] == [1]
    assert [(r.seed, r.frames, r.total_frames) for r in group.unfinished] == [(2, 400, 600)]


def test_unreadable_config_names_the_run(tmp_path, make_run):
    run = make_run(tmp_path / "a")
    (run / "config.json").write_text("{not json")
    with pytest.raises(ReportError, match="Cannot read the run in"):
        find_runs(tmp_path)


def test_late_mean_averages_the_last_fifth_of_epochs_skipping_empty_cells(tmp_path, make_run):
    # Ten epochs: the last 20% are the last two rows. Their numbers, by hand: (7 + 9) / 2; one
    # empty cell among them leaves the other; a column no row holds, or none of the late rows,
    # gives NaN.
    curve = {"frames": list(range(100, 1100, 100)),
             "train/cost": [50.0] * 8 + [7.0, 9.0],
             "train/reward": [1.0] * 8 + ["", 4.0],
             "probe/auc": [0.5] * 8 + ["", ""]}
    (run,) = find_runs(make_run(tmp_path / "run", curve=curve))
    assert run.late_mean("train/cost") == pytest.approx(8.0)
    assert run.late_mean("train/reward") == pytest.approx(4.0)
    assert math.isnan(run.late_mean("probe/auc")) and math.isnan(run.late_mean("eval/missing"))
