"""s3rl-report gap: one algo against another on the same tasks under several presets, checked
against hand computations, scipy's paired t-test and the report's own aggregate (the same
rliable estimate built from groups)."""

from __future__ import annotations

import json
import math

import pytest
from scipy import stats

from s3rl_torchrl.report.aggregate import aggregate
from s3rl_torchrl.report.cli import main
from s3rl_torchrl.report.gap import format_difference, gap
from s3rl_torchrl.report.runs import ReportError, find_runs, group_runs
from s3rl_torchrl.report.stats import paired_seed_test
from tests.report.conftest import episodes

CHEETAH = "SafetyHalfCheetahVelocity-v1"
CIRCLE = "SafetyPointCircle1-v0"


@pytest.fixture
def presets(tmp_path, make_run):
    """paper: both tasks, seeds 10/20/30 (s3rl cheaper on PointCircle1 by 20, 30, 40);
    safe: PointCircle1 only (CHEETAH's sac_lag missing), spread over two trees."""
    paper, safe_a, safe_b = tmp_path / "paper", tmp_path / "safe_a", tmp_path / "safe_b"
    costs = {CIRCLE: {"s3rl": (5, 6, 7), "sac_lag": (25, 36, 47)},
             CHEETAH: {"s3rl": (1, 12, 3), "sac_lag": (2, 2, 2)}}
    for task, by_algo in costs.items():
        for algo, values in by_algo.items():
            for seed, cost in zip((10, 20, 30), values):
                make_run(paper / f"{algo}_{task}/seed{seed}", task, algo, seed,
                         episodes(100 + seed, cost))
    for seed, (c_ref, c_base) in zip((10, 20, 30), ((4, 5), (8, 6), (6, 7))):
        make_run(safe_a / f"s3rl/seed{seed}", CIRCLE, "s3rl", seed, episodes(50, c_ref))
        make_run(safe_b / f"sac_lag/seed{seed}", CIRCLE, "sac_lag", seed,
                 episodes(40 + seed, c_base))
    make_run(safe_a / "s3rl_cheetah/seed10", CHEETAH, "s3rl", 10, episodes(3, 3))
    return {"paper": [paper], "safe": [safe_a, safe_b]}


def test_differences_per_task_and_setting_against_scipy(presets):
    result = gap(presets, reps=200)
    assert result.tasks == [CHEETAH, CIRCLE]
    paper = result.rows[CIRCLE, "paper"]
    expected = stats.ttest_rel([5, 6, 7], [25, 36, 47])
    assert paper.cost_test.difference == pytest.approx(-30.0)
    assert paper.cost_test.pvalue == pytest.approx(expected.pvalue)
    assert paper.mean("sac_lag", "cost") == pytest.approx(36.0)
    safe = result.rows[CIRCLE, "safe"]  # both trees read as one setting
    assert safe.cost_test.difference == pytest.approx((4 + 8 + 6 - 5 - 6 - 7) / 3)
    assert safe.reward_test.difference == pytest.approx(50 - 60)  # 50 against 50, 60, 70
    # The paper's Table 1 (Lag rows): PointCircle1 5.17 against 32.65.
    assert result.paper_difference(CIRCLE, "cost") == pytest.approx(5.17 - 32.65)
    assert result.paper_difference(CIRCLE, "reward") == pytest.approx(37.54 - 22.15)
    # Either way round; an algo the paper's Table 1 does not have gives none.
    swapped = gap(presets, reference="sac_lag", baseline="s3rl", reps=50)
    assert swapped.paper_difference(CIRCLE, "cost") == pytest.approx(32.65 - 5.17)
    assert swapped.rows[CIRCLE, "paper"].cost_test.difference == pytest.approx(30.0)
    assert math.isnan(gap(presets, baseline="ppo_lag", reps=50).paper_difference(CIRCLE, "cost"))
    # Only the cheetah's s3rl seed 10 under safe: the row is there, incomplete, untested.
    cheetah = result.rows[CHEETAH, "safe"]
    assert not cheetah.complete and math.isnan(cheetah.cost_test.pvalue)
    assert result.missing == [f"safe: {CHEETAH} sac_lag"]
    assert result.shared == [CIRCLE]


def test_each_settings_answer_is_the_reports_rliable_estimate(presets):
    result = gap(presets, reps=300, seed=3)
    answers = {a.setting: a for a in result.answers}
    assert answers["paper"].tasks == [CHEETAH, CIRCLE] and answers["safe"].tasks == [CIRCLE]
    assert answers["paper"].runs == (6, 6)
    # PointCircle1 under paper: every s3rl run is cheaper than every sac_lag run -> 1; the
    # cheetah: s3rl costs 1, 12, 3 against 2, 2, 2 -> only the 1 is cheaper: 3 of 9 pairs.
    assert answers["paper"].lower_cost.point == pytest.approx((1.0 + 3 / 9) / 2)
    # Under safe (PointCircle1): 4, 8, 6 against 5, 6, 7 -> cheaper pairs 3 + 0 + 1, and the
    # tie 6 = 6 counts one half: 4.5 of 9.
    assert answers["safe"].lower_cost.point == pytest.approx(4.5 / 9)
    # The same runs through the report's aggregate: the same point and bootstrap interval.
    read = aggregate(group_runs(find_runs(presets["paper"][0])), reps=300, seed=3)
    (pair,) = read.protocols[0].pairs
    assert answers["paper"].lower_cost == pair.cost
    assert answers["paper"].higher_reward == pair.reward


def test_the_delivered_protocol_reads_a_run_without_a_pick_by_its_last_policy(presets):
    run = presets["safe"][0] / "s3rl/seed10"
    final = json.loads((run / "final_eval.json").read_text())
    final["delivered"] = {"reward_mean": 70.0, "cost_mean": 1.0}
    (run / "final_eval.json").write_text(json.dumps(final))
    config = json.loads((run / "config.json").read_text())
    config["eval"]["delivery_epochs"] = 10
    (run / "config.json").write_text(json.dumps(config))
    row = gap(presets, protocol="delivered", reps=50).rows[CIRCLE, "safe"]
    assert row.seeds["s3rl"][10] == (70.0, 1.0)  # the pick
    assert row.seeds["s3rl"][20] == (50.0, 8.0)  # no pick: its last policy
    assert gap(presets, protocol="last", reps=50).rows[CIRCLE, "safe"].seeds["s3rl"][10] == \
        (50.0, 4.0)


def test_bad_input_is_refused_with_the_reason(presets, make_run, tmp_path):
    with pytest.raises(ReportError, match="Unknown protocol 'best'; valid: last"):
        gap(presets, protocol="best")
    with pytest.raises(ReportError, match="both 's3rl'"):
        gap(presets, baseline="s3rl")
    with pytest.raises(ReportError, match="'none' has no run of ddpg_lag or ppo_lag"):
        gap({"none": presets["safe"]}, reference="ddpg_lag", baseline="ppo_lag")
    with pytest.raises(ReportError, match="give each preset's runs once"):
        gap({"twice": presets["paper"] * 2})
    make_run(tmp_path / "limit/seed40", CIRCLE, "s3rl", 40, episodes(1, 1),
             task__cost_limit=25.0)
    with pytest.raises(ReportError, match="different cost limits \\(10, 25\\)"):
        gap({"paper": presets["paper"] + [tmp_path / "limit"]})


def test_cli_writes_the_page_and_the_json(presets, tmp_path, capsys):
    out, record = tmp_path / "gap.md", tmp_path / "gap.json"
    safe = ",".join(str(t) for t in presets["safe"])
    assert main(["gap", "--setting", f"paper={presets['paper'][0]}", "--setting",
                 f"safe={safe}", "--reps", "100", "--out", str(out), "--json", str(record)]) == 0
    page = out.read_text()
    assert f"| {CIRCLE} | paper | 6.00 (3) | 36.00 (3) | -30.00 [" in page
    assert "|  | safe | 6.00 (3) | 6.00 (3) | +0.00 [" in page
    assert "-27.48 |" in page  # the paper's 5.17 - 32.65 beside PointCircle1's first row
    assert f"| safe | 1: {CIRCLE} | 3 / 3 | 0.50 [" in page
    assert f"Without a finished run: safe: {CHEETAH} sac_lag." in page
    data = json.loads(record.read_text())
    assert data["shared_tasks"] == [CIRCLE]
    row = next(r for r in data["rows"] if r["task"] == CIRCLE and r["setting"] == "paper")
    assert row["seeds"]["sac_lag"]["20"] == {"reward": 120.0, "cost": 36.0}
    assert row["paper_cost_difference"] == pytest.approx(-27.48)
    with pytest.raises(SystemExit):
        main(["gap", "--setting", "no-trees", "--out", str(out)])
    with pytest.raises(SystemExit):
        main(["gap", "--setting", f"a={safe}", "--setting", f"a={safe}", "--out", str(out)])
    assert "each --setting needs its own name" in capsys.readouterr().err
    assert main(["gap", "--setting", f"x={tmp_path / 'nowhere'}", "--out", str(out)]) == 2
    assert "s3rl-report gap: error:" in capsys.readouterr().err


def test_no_setting_answers_on_a_task_the_first_has_one_algo_of(presets, make_run):
    # The first setting (paper) gains a task with only s3rl's runs; safe has both algos of it.
    # Its per-task rows show it, but no answer is over it: the settings stay comparable.
    hopper = "SafetyHopperVelocity-v1"
    make_run(presets["paper"][0] / f"s3rl_{hopper}/seed10", hopper, "s3rl", 10, episodes(9, 1))
    for algo, cost in (("s3rl", 2), ("sac_lag", 9)):
        make_run(presets["safe"][0] / f"{algo}_{hopper}/seed10", hopper, algo, 10,
                 episodes(9, cost))
    result = gap(presets, reps=50)
    assert hopper in result.tasks and result.rows[hopper, "safe"].complete
    answers = {a.setting: a for a in result.answers}
    assert answers["paper"].tasks == [CHEETAH, CIRCLE] and answers["safe"].tasks == [CIRCLE]


def test_a_difference_cell_says_why_its_test_is_undefined():
    # scipy's ttest_rel: 20, 30, 40 against 5, 6, 7 (a spread of differences) gives a p and an
    # interval; the same cost on every seed of both algos (SafetyBallRun-v0 under the paper's
    # settings: 92 of 100 steps) leaves t undefined; the same shift on every seed gives scipy's
    # p of 0 (t infinite), kept but flagged; one pair is no test at all.
    spread = paired_seed_test({10: 20.0, 20: 30.0, 30: 40.0}, {10: 5.0, 20: 6.0, 30: 7.0})
    expected = stats.ttest_rel([20, 30, 40], [5, 6, 7])
    interval = expected.confidence_interval(0.95)
    assert format_difference(spread) == (
        f"+24.00 [{interval.low:+.2f}, {interval.high:+.2f}], p {expected.pvalue:.2f}")
    same = paired_seed_test({s: 92.0 for s in (10, 20, 30)}, {s: 92.0 for s in (10, 20, 30)})
    assert format_difference(same) == "+0.00 (3 pairs; no variance)"
    shifted = paired_seed_test({10: 3.0, 20: 4.0, 30: 5.0}, {10: 1.0, 20: 2.0, 30: 3.0})
    assert format_difference(shifted) == "+2.00 [+2.00, +2.00], p 0.00 (no variance)"
    assert format_difference(paired_seed_test({10: 3.0}, {10: 1.0})) == (
        "+2.00 (1 pair; needs >= 2 seeds run by both)")
    assert format_difference(paired_seed_test({10: 3.0}, {20: 1.0})) == "–"
