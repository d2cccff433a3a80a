"""research/studies/lagrangian_dynamics.py: a launch of tiny runs end to end (alone and as a
group of seeds in one process), the controllers on the synthetic plant, and every setting
composing to the controller it names. Its statistics are s3rl-report lagrangian's
(tests/report/test_lagrangian_summary.py)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "research" / "studies"))
import lagrangian_dynamics as ld  # noqa: E402


@pytest.mark.slow
def test_launch_a_group_of_seeds_in_one_process_then_skip_it(tmp_path, capsys):
    args = ["launch", "--experiment", "tiny", "--settings", "pid_ema", "--seeds", "1", "2"]
    args += ["--frames", "400", "--group", "--no-compile", "--runs-dir", str(tmp_path / "runs")]
    args += ["--algo", "s3rl"]
    report = ld.main(args)
    (row,) = report["settings"]
    assert row["algo"] == "s3rl" and row["seeds"] == [1, 2] and row["frames"] == 400
    assert row["setting"] == "pid(kp=0.05,ki=0.0005,kd=0.1,ema=0.95,delay=10) ups=0.25 batch=100"
    # Any algo but SAC-Lag gets its own level, so its groups never resume SAC-Lag's.
    group = tmp_path / "runs" / "SafetyHalfCheetahVelocity-v1" / "s3rl" / "pid_ema"
    assert (group / "seeds.json").is_file()
    for seed in (1, 2):
        config = json.loads((group / f"seed{seed}" / "config.json").read_text())
        assert config["seed"] == seed and config["algo"]["pid"]["ema_alpha"] == 0.95
        assert config["algo"]["name"] == "s3rl"
        assert (group / f"seed{seed}" / "final_eval.json").is_file()
    launched = capsys.readouterr().out
    assert launched.count("launch:") == 1 and "seeds=[1,2]" in launched
    ld.main(args)  # finished: nothing is launched again
    assert "launch:" not in capsys.readouterr().out


@pytest.mark.slow
def test_launch_two_settings_of_tiny_runs_then_skip_them(tmp_path, capsys):
    args = ["launch", "--experiment", "tiny", "--settings", "fsrl", "pid_ema", "--seeds", "1"]
    args += ["--frames", "400", "--no-compile", "--jobs", "2", "--runs-dir", str(tmp_path / "runs")]
    report = ld.main([*args, "--csv-dir", str(tmp_path / "csv")])
    fsrl, ema = sorted(report["settings"], key=lambda r: "ema" in r["setting"])
    assert fsrl["setting"] == "pid(kp=0.05,ki=0.0005,kd=0.1) ups=0.25 batch=100"
    assert ema["setting"] == "pid(kp=0.05,ki=0.0005,kd=0.1,ema=0.95,delay=10) ups=0.25 batch=100"
    for row in (fsrl, ema):
        assert row["frames"] == 400 and row["seeds"] == [1]
        assert not math.isnan(row["eval_reward"]) and not math.isnan(row["final_reward"])
    copies = sorted(p.relative_to(tmp_path / "csv") for p in (tmp_path / "csv").rglob("*.csv"))
    assert len(copies) == 2 and all(p.name == "seed1.csv" for p in copies)
    run_dir = tmp_path / "runs" / "SafetyHalfCheetahVelocity-v1" / "pid_ema" / "seed1"
    config = json.loads((run_dir / "config.json").read_text())
    assert config["algo"]["pid"]["ema_alpha"] == 0.95 and config["algo"]["name"] == "sac_lag"
    capsys.readouterr()
    ld.main(args)  # both finished: nothing is launched again
    assert "launch:" not in capsys.readouterr().out


def test_plant_mode_builds_the_configured_controllers(tmp_path):
    report = ld.main(["plant", "--noise", "0", "--seeds", "0", "--updates", "4"])
    rows = {r["setting"]: r for r in report["settings"]}
    # By hand (tests/objectives/test_lagrangian.py): FSRL's form from J = 900, 0, 900, 0 ...
    assert rows["fsrl"]["first_lambdas_seed0"] == [133.945, 0.0, 135.385, 0.38]
    # ... pid=ema's first update 0.05 * 44.5 + 0.0005 * 890 + 0.1 * 44.5; Adam's first steps = lr
    assert rows["pid_ema"]["first_lambdas_seed0"][0] == pytest.approx(7.12)
    # ... the same with ki = 0.01: 0.05 * 44.5 + 0.01 * 890 + 0.1 * 44.5
    assert rows["pid_ema_ki0.01"]["first_lambdas_seed0"][0] == pytest.approx(15.575)
    assert rows["learned"]["first_lambdas_seed0"][:2] == pytest.approx([0.005, 0.01], abs=1e-6)
    assert rows["learned_lr0.05"]["first_lambdas_seed0"][0] == pytest.approx(0.05, abs=1e-6)
    # Second half (updates 3, 4): J = 900 then 0 for FSRL, over the limit once in two.
    assert rows["fsrl"]["cost_over_limit"] == 0.5


@pytest.mark.parametrize("experiment", ["paper", "safe"])
def test_every_setting_composes_to_the_controller_it_names(experiment):
    """pid=... sets only the PID's gains and experiment=safe picks the learned multiplier, so a
    PID setting that does not name its controller would run `learned` under --experiment safe
    (two settings, one controller)."""
    from hydra import compose, initialize_config_dir

    from s3rl_torchrl.trainer import register_configs, validate

    register_configs()
    with initialize_config_dir(config_dir=str(ld.REPO / "configs"), version_base="1.3"):
        for name, overrides in ld.SETTINGS.items():
            cfg = validate(compose(config_name="train", overrides=[
                f"experiment={experiment}", "algo=sac_lag", *ld.BASE_OVERRIDES, *overrides,
            ]))
            expected = "learned" if "learned" in name else "pid"
            assert cfg.algo.lagrangian == expected, name
