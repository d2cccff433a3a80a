"""s3rl-report lagrangian (report/lagrangian.py): second-half statistics against hand-made runs,
the table, the copied CSVs, the figure and the command line."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from s3rl_torchrl.report import lagrangian as ld
from s3rl_torchrl.report.cli import main

COLUMNS = ["frames", "epoch", "train/reward", "train/cost", "lagrangian"]
COLUMNS += ["eval/reward", "eval/cost"]


def fake_run(root: Path, seed: int, rows: list[list[float]], updates, final=None) -> Path:
    run = root / f"seed{seed}"
    (run / "logs" / "exp" / "scalars" / "lagrangian").mkdir(parents=True)
    config = {
        "task": {"name": "SafetyHalfCheetahVelocity-v1", "cost_limit": 10.0},
        "algo": {
            "name": "sac_lag",
            "lagrangian": "pid",
            "lagrangian_lr": 0.005,
            "pid": {
                "kp": 0.05,
                "ki": 0.0005,
                "kd": 0.1,
                "ema_alpha": 0.0,
                "derivative_delay": 1,
                "penalty_max": None,
            },
        },
        "collector": {"frames_per_batch": 20000},
        "seed": seed,
    }
    (run / "config.json").write_text(json.dumps(config))
    with (run / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        writer.writerows(rows)
    with (run / "logs" / "exp" / "scalars" / "lagrangian" / "value.csv").open("w") as f:
        f.writelines(f"{frames},{lam}\n" for frames, lam in updates)
    if final is not None:
        (run / "final_eval.json").write_text(
            json.dumps({"reward_mean": final[0], "cost_mean": final[1]})
        )
    return run


def test_second_half_statistics_by_hand(tmp_path):
    nan = float("nan")
    # frames, epoch, train reward, train cost, lambda, eval reward, eval cost
    rows = [
        [20000, 1, 0.0, 0.0, 0.0, 100.0, 700.0],
        [40000, 2, 0.0, 650.0, 90.0, 100.0, 0.0],
        [60000, 3, 0.0, nan, 1.0, 100.0, 800.0],
        [80000, 4, 2000.0, 20.0, 100.0, 3000.0, 900.0],  # second half: frames > 60000
        [100000, 5, 500.0, 15.0, 0.5, -100.0, 0.0],
        [120000, 6, 800.0, 0.0, 2.0, 1000.0, 5.0],
    ]
    updates = [(20000, 0), (40000, 90), (60000, 1), (80000, 100), (90000, 50), (100000, 0.5)]
    updates.append((120000, 2))
    a = fake_run(tmp_path, 10, rows, updates, final=(2500.0, 3.0))
    s = ld.summarise_run(a)
    assert s["setting"] == "pid(kp=0.05,ki=0.0005,kd=0.1) batch=20000"
    assert (s["frames"], s["epochs_second_half"], s["seed"]) == (120000, 3, 10)
    assert s["eval_cost_over_limit"] == pytest.approx(1 / 3)  # 900 | 0, 5
    assert s["train_cost_over_limit"] == pytest.approx(2 / 3)  # 20, 15 | 0
    # (train, eval) cost: (20, 900) both over, (15, 0) training over only, (0, 5) both within.
    assert (s["train_over_eval_within"], s["train_within_eval_over"]) == (pytest.approx(1 / 3), 0)
    assert s["mean_abs_dlambda_epoch"] == pytest.approx((99.5 + 1.5) / 2)
    assert s["mean_abs_dlambda_update"] == pytest.approx((50 + 49.5 + 1.5) / 3)
    assert s["lambda_mean"] == pytest.approx(102.5 / 3)
    assert s["eval_reward"] == pytest.approx(1300.0)
    assert s["eval_cost"] == pytest.approx(905 / 3)
    assert s["train_cost"] == pytest.approx(35 / 3)
    # Deviations from the mean 35/3: 25/3, 10/3, -35/3; pairs (25/3)(10/3) + (10/3)(-35/3).
    assert s["train_cost_autocorr"] == pytest.approx((250 - 350) / (625 + 100 + 1225))
    assert (s["final_reward"], s["final_cost"]) == (2500.0, 3.0)
    # The last 20% of 6 epochs: round(1.2) = 1 epoch, the last.
    assert (s["eval_reward_last20"], s["eval_cost_last20"]) == (1000.0, 5.0)
    assert s["train_cost_last20"] == 0.0
    # The multiplier over the whole run: highest 100 at 80000 frames, 2 at the end.
    assert (s["lambda_peak"], s["lambda_peak_frames"], s["lambda_end"]) == (100.0, 80000, 2.0)

    # A second seed of the same setting: every late eval cost over the limit, no final eval.
    rows_b = [[r[0], r[1], r[2], r[3], r[4] * 2, r[5], 50.0] for r in rows]
    b = fake_run(tmp_path, 20, rows_b, updates)
    report = ld.summarise([a, b, tmp_path / "not_a_run"], tmp_path / "s.json", None, None)
    (row,) = report["settings"]
    assert row["seeds"] == [10, 20]
    assert row["eval_cost_over_limit"] == pytest.approx((1 / 3 + 1) / 2)
    assert row["eval_cost_over_limit_std"] == pytest.approx(math.sqrt(2 * (1 / 3) ** 2))
    assert row["mean_abs_dlambda_epoch"] == pytest.approx((50.5 + 101) / 2)
    assert row["final_reward"] == 2500.0 and math.isnan(row["final_reward_std"])
    assert row["eval_cost_last20"] == pytest.approx((5.0 + 50.0) / 2)
    # Seed 20: (20, 50), (15, 50) both over, (0, 50) evaluation over only.
    assert row["train_within_eval_over"] == pytest.approx((0 + 1 / 3) / 2)
    assert row["train_over_eval_within"] == pytest.approx((1 / 3 + 0) / 2)
    assert (row["lambda_peak"], row["lambda_end"]) == (150.0, 3.0)  # seed 20's are twice seed 10's
    line = ld.markdown(report["settings"]).splitlines()[-1]
    assert line.endswith("| 1000 | 27.5 | 2500 | 3.0 |")  # one final evaluation: no std
    saved = json.loads((tmp_path / "s.json").read_text())
    assert saved["settings"][0]["seeds"] == [10, 20] and len(saved["runs"]) == 2


def test_lag1_autocorrelation_by_hand():
    nan = float("nan")
    # A period-2 cycle: deviations -50, 50, -50, 50, three pairs of -2500 over 4 x 2500.
    assert ld.lag1_autocorrelation([0.0, 100.0, 0.0, 100.0]) == pytest.approx(-0.75)
    # A ramp: mean 2, deviations -2..2: pairs 2 + 0 + 0 + 2 = 4 over 10.
    assert ld.lag1_autocorrelation([0.0, 1.0, 2.0, 3.0, 4.0]) == pytest.approx(0.4)
    # Epochs without a training episode (NaN) break their pairs, not the series' mean.
    assert ld.lag1_autocorrelation([0.0, 100.0, nan, 0.0, 100.0]) == pytest.approx(-0.5)
    assert math.isnan(ld.lag1_autocorrelation([5.0, 5.0, 5.0]))  # no variance
    assert math.isnan(ld.lag1_autocorrelation([1.0, nan, 2.0]))  # too short


def test_until_reads_a_run_as_if_it_had_stopped_there(tmp_path):
    nan = float("nan")
    rows = [
        [20000, 1, 0.0, 0.0, 0.0, 100.0, 700.0],
        [40000, 2, 0.0, 650.0, 90.0, 100.0, 0.0],
        [60000, 3, 0.0, nan, 1.0, 100.0, 800.0],  # second half of 100000: frames > 50000
        [80000, 4, 2000.0, 20.0, 100.0, 3000.0, 900.0],
        [100000, 5, 500.0, 15.0, 0.5, -100.0, 0.0],
        [120000, 6, 800.0, 0.0, 2.0, 1000.0, 5.0],  # after the cut
    ]
    updates = [(20000, 0), (40000, 90), (60000, 1), (80000, 100), (90000, 50), (100000, 0.5)]
    updates.append((120000, 2))
    run = fake_run(tmp_path, 10, rows, updates, final=(2500.0, 3.0))
    s = ld.summarise_run(run, until=100000)
    assert (s["frames"], s["epochs_second_half"]) == (100000, 3)
    assert s["eval_cost_over_limit"] == pytest.approx(2 / 3)  # 800, 900 | 0
    assert s["train_cost_over_limit"] == 1.0  # 20, 15 (the NaN epoch has no episode)
    assert s["mean_abs_dlambda_epoch"] == pytest.approx((99 + 99.5) / 2)
    assert s["mean_abs_dlambda_update"] == pytest.approx((99 + 50 + 49.5) / 3)
    # The final evaluation belongs to the whole run, not to its first 100000 frames.
    assert math.isnan(s["final_reward"]) and math.isnan(s["final_cost"])


def test_algos_with_the_same_controller_are_summarised_apart(tmp_path):
    rows = [[20000, 1, 0.0, 0.0, 0.0, 100.0, 700.0], [40000, 2, 0.0, 50.0, 9.0, 100.0, 0.0]]
    sac_lag = fake_run(tmp_path / "sac_lag", 10, rows, [(20000, 0.0), (40000, 9.0)])
    s3rl = fake_run(tmp_path / "s3rl", 10, rows, [(20000, 0.0), (40000, 9.0)])
    config = json.loads((s3rl / "config.json").read_text())
    config["algo"]["name"] = "s3rl"
    (s3rl / "config.json").write_text(json.dumps(config))
    report = ld.summarise([sac_lag, s3rl], None, tmp_path / "csv", None)
    assert [(r["algo"], r["seeds"]) for r in report["settings"]] == [
        ("s3rl", [10]),
        ("sac_lag", [10]),
    ]
    task_dir = tmp_path / "csv" / "SafetyHalfCheetahVelocity-v1"
    copies = sorted(p.relative_to(task_dir).as_posix() for p in task_dir.rglob("*.csv"))
    assert copies == [
        "pid_kp_0.05_ki_0.0005_kd_0.1_batch_20000/seed10.csv",
        "s3rl/pid_kp_0.05_ki_0.0005_kd_0.1_batch_20000/seed10.csv",
    ]


def test_plot_has_a_pair_of_rows_per_setting_and_a_column_per_seed(tmp_path):
    rows = [[20000, 1, 0.0, 0.0, 0.0, 100.0, 700.0], [40000, 2, 0.0, 50.0, 9.0, 100.0, 0.0]]
    updates = [(20000, 0.0), (40000, 9.0)]
    runs = [fake_run(tmp_path / "sac_lag", seed, rows, updates) for seed in (20, 10)]
    s3rl = fake_run(tmp_path / "s3rl", 10, rows, updates)
    config = json.loads((s3rl / "config.json").read_text())
    config["algo"]["name"] = "s3rl"
    (s3rl / "config.json").write_text(json.dumps(config))
    summaries = [ld.summarise_run(r) for r in [*runs, s3rl]]
    fig = ld.plot(summaries, tmp_path / "dynamics.png")
    assert (tmp_path / "dynamics.png").stat().st_size > 0
    grid = fig.axes[0].get_subplotspec().get_gridspec()
    assert (grid.nrows, grid.ncols) == (4, 2)  # (lambda, cost) x 2 settings, 2 seeds at most
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 6  # s3rl has one seed: its second column stays empty
    assert [ax.get_title().split("\n")[0] for ax in visible if ax.get_title()] == [
        "HalfCheetahVelocity-v1 sac_lag seed 10",
        "HalfCheetahVelocity-v1 sac_lag seed 20",
        "HalfCheetahVelocity-v1 s3rl seed 10",
    ]


def test_the_subcommand_writes_the_summary_with_its_command(tmp_path, capsys):
    rows = [[20000, 1, 0.0, 0.0, 0.0, 100.0, 700.0], [40000, 2, 0.0, 50.0, 9.0, 100.0, 0.0]]
    run = fake_run(tmp_path / "runs", 10, rows, [(20000, 0.0), (40000, 9.0)])
    argv = ["lagrangian", str(run), str(tmp_path / "not_a_run"), "--out", str(tmp_path / "l.json"),
            "--csv-dir", str(tmp_path / "csv"), "--until", "40000"]
    assert main(argv) == 0
    saved = json.loads((tmp_path / "l.json").read_text())
    assert saved["command"] == "s3rl-report " + " ".join(argv)
    assert list(saved) == ["command", "machine", "runs", "settings"]
    assert saved["settings"][0]["seeds"] == [10] and saved["runs"][0]["frames"] == 40000
    assert len(list((tmp_path / "csv").rglob("seed10.csv"))) == 1
    out = capsys.readouterr()
    assert out.out.startswith("| task | algo | setting |") and "skipping" in out.err


def test_a_report_of_a_directory_named_like_a_subcommand_is_written_with_a_path(tmp_path):
    from s3rl_torchrl.report.cli import SUBCOMMANDS, parse_args

    assert set(SUBCOMMANDS) == {"lagrangian", "compare-runs", "before-after", "gap"}
    # The report's own arguments are as before: RUNS first, then its options.
    args = parse_args(["./lagrangian", "--out", str(tmp_path)])
    assert (args.runs, args.out) == (["./lagrangian"], str(tmp_path))


_FSRL = {"cost_critic_read": "min", "cost_nonnegative": False, "cost_entropy": True,
         "entropy_rescaling": True}


def test_the_setting_names_the_critics_and_what_else_a_selection_varies():
    config = {
        "algo": {"lagrangian": "learned", "lagrangian_lr": 3e-6, "lagrangian_cadence": "step",
                 "lagrangian_window": 20, "lagrangian_warmup_frames": 100000,
                 "cost_critic_read": "min", "cost_nonnegative": False, "cost_entropy": True,
                 "entropy_rescaling": True, "cost_gamma": None, "update_per_step": 0.2},
        "collector": {"frames_per_batch": 1000},
    }
    base = "learned(lr=3e-06) step(window=20,warmup=100000)"
    assert ld.setting_name(config) == f"{base} batch=1000"  # FSRL's critics: as before
    config["algo"] |= {"cost_critic_read": "max", "cost_nonnegative": True,
                       "cost_entropy": False, "entropy_rescaling": False}
    assert ld.setting_name(config) == f"{base} sound(read=max) batch=1000"
    # A run made before cost_gamma left the package (algorithms.config.REMOVED_OPTIONS) with
    # another value than its default keeps it in its setting, apart from the others.
    config["algo"] |= {"cost_critic_read": "mean", "cost_gamma": 0.9, "update_per_step": 0.5}
    expected = f"{base} sound(read=mean) cost_gamma=0.9 ups=0.5 batch=1000"
    assert ld.setting_name(config) == expected
    config["algo"]["cost_nonnegative"] = False
    assert "critic(read=mean)" in ld.setting_name(config)
    # The targets' own read is named where it differs from the actor loss's, FSRL's min too.
    config["algo"] |= {"cost_nonnegative": True, "cost_critic_read": "max",
                       "cost_target_read": "mean"}
    assert "sound(read=max,target=mean)" in ld.setting_name(config)
    config["algo"] |= {"cost_target_read": "max"}
    assert "sound(read=max)" in ld.setting_name(config)
    config["algo"] |= _FSRL | {"cost_target_read": "mean"}
    assert ld.setting_name(config).startswith(f"{base} critic(read=min,target=mean)")


def test_where_the_multiplier_lets_go_by_hand(tmp_path):
    # frames, epoch, train reward, train cost, lambda, eval reward, eval cost; limit 10.
    rows = [
        [20000, 1, 0.0, 0.0, 3.0, 100.0, 50.0],
        [40000, 2, 0.0, 0.0, 2.0, 100.0, 50.0],  # first half: frames <= 60000
        [60000, 3, 0.0, 0.0, 0.0, 100.0, 0.0],
        [80000, 4, 0.0, 12.0, 0.01, 40.0, 30.0],  # released, over the limit
        [100000, 5, 0.0, 5.0, 0.04, 20.0, 10.0],  # released, at the limit: within
        [120000, 6, 0.0, 8.0, 0.8, 30.0, 0.0],
        [140000, 7, 0.0, 11.0, 0.05, 60.0, 12.0],  # 0.05 is not below 0.05
    ]
    s = ld.summarise_run(fake_run(tmp_path, 10, rows, []))
    assert s["epochs_second_half"] == 4  # frames > 70000
    assert s["lambda_min"] == 0.01
    assert s["lambda_near_zero"] == pytest.approx(2 / 4)
    assert s["eval_cost_over_limit_near_zero"] == pytest.approx(1 / 2)
    assert s["eval_reward_over_limit"] == pytest.approx((40.0 + 60.0) / 2)
    assert s["eval_reward_within_limit"] == pytest.approx((20.0 + 30.0) / 2)

    # Never released: no epoch to read an overshoot from.
    held = [r[:4] + [1.0] + r[5:] for r in rows]
    s = ld.summarise_run(fake_run(tmp_path, 20, held, []))
    assert (s["lambda_min"], s["lambda_near_zero"]) == (1.0, 0.0)
    assert math.isnan(s["eval_cost_over_limit_near_zero"])
