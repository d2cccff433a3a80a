"""s3rl-report before-after: two presets' runs paired per task, algo and seed, checked against
numbers computed by hand and scipy's paired t-test."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from scipy import stats

from s3rl_torchrl.report.before_after import MISS_CAUSES, TARGET_KINDS, before_after
from s3rl_torchrl.report.cli import main
from s3rl_torchrl.report.runs import ReportError
from tests.report.conftest import episodes

TASK = "SafetyHalfCheetahVelocity-v1"


@pytest.fixture
def trees(tmp_path, make_run):
    # Before: seeds 10/20/30 of sac_lag cost 4, 12, 30 (one within 10) at reward 100, 120, 140;
    # after: cost 3, 8, 9 (all within) at reward 90, 110, 100. s3rl: one seed on each side only,
    # and a finished-before / unfinished-after seed.
    before, after = tmp_path / "before", tmp_path / "after"
    for seed, (r0, c0, r1, c1) in zip((10, 20, 30), [(100, 4, 90, 3), (120, 12, 110, 8),
                                                     (140, 30, 100, 9)]):
        make_run(before / f"sac_lag/seed{seed}", TASK, "sac_lag", seed, episodes(r0, c0))
        make_run(after / f"sac_lag/seed{seed}", TASK, "sac_lag", seed, episodes(r1, c1))
    make_run(before / "s3rl/seed10", TASK, "s3rl", 10, episodes(50, 5))
    make_run(after / "s3rl/seed10", TASK, "s3rl", 10, episodes(40, 6))
    make_run(before / "s3rl/seed20", TASK, "s3rl", 20, episodes(50, 5))
    make_run(after / "s3rl/seed20", TASK, "s3rl", 20, episodes(50, 5), finished=False)
    make_run(after / "s3rl/seed30", TASK, "s3rl", 30, episodes(50, 5))
    return before, after


def test_pairs_by_seed_and_counts_runs_within_the_limit(trees):
    before, after = trees
    result = before_after([before], [after], within_target={"sac_lag": 3})
    sac = next(r for r in result.rows if r.algo == "sac_lag")
    assert [p.seed for p in sac.pairs] == [10, 20, 30]
    assert sac.within("before") == 1 and sac.within("after") == 3
    assert sac.mean("before_cost") == pytest.approx(46 / 3)
    expected = stats.ttest_rel([3, 8, 9], [4, 12, 30])
    assert sac.cost_test.difference == pytest.approx((3 + 8 + 9 - 4 - 12 - 30) / 3)
    assert sac.cost_test.pvalue == pytest.approx(expected.pvalue)
    assert result.within("sac_lag", "after") == (3, 3)
    s3rl = next(r for r in result.rows if r.algo == "s3rl")
    assert [p.seed for p in s3rl.pairs] == [10]
    assert math.isnan(s3rl.cost_test.pvalue)  # one pair: no test
    assert result.unpaired == [(TASK, "s3rl", 20, "unfinished"), (TASK, "s3rl", 30, "after only")]
    targets = {t.name.split(":")[0]: t for t in result.targets}
    assert targets["sac_lag"].met and targets["s3rl"].met  # 3 of 3; s3rl: 1 of 1 by default
    # Reward kept only where the old mean cost was within the limit: s3rl (5 <= 10), 40 / 50.
    kept = [t for t in result.targets if "reward kept" in t.name]
    assert [t.name.split()[0] for t in kept] == ["s3rl"] and not kept[0].met
    assert "0.80 of 50.0" in kept[0].value


def test_a_reward_miss_shows_the_training_reward_kept_beside_it(tmp_path, make_run):
    # Two seeds within the limit before (cost 5). Their final rewards: before 100 and 60, after
    # 40 and 20 (kept: 30 / 80 = 0.375). Training reward over the last 20% of 10 epochs (the last
    # two): before (70 + 90) / 2 = 80 and 50 (mean 65), after 60 and (30 + 50) / 2 = 40 (mean
    # 50): 50 / 65 = 0.77 of it kept in training, the rest lost at the final evaluation.
    before, after = tmp_path / "before", tmp_path / "after"
    frames = list(range(100, 1100, 100))
    runs = {10: ((100, [0.0] * 8 + [70.0, 90.0]), (40, [0.0] * 8 + [60.0, 60.0])),
            20: ((60, [0.0] * 8 + [50.0, 50.0]), (20, [0.0] * 8 + [30.0, 50.0]))}
    for seed, ((old_reward, old_curve), (new_reward, new_curve)) in runs.items():
        make_run(before / f"seed{seed}", TASK, "s3rl", seed, episodes(old_reward, 5),
                 curve={"frames": frames, "train/reward": old_curve})
        make_run(after / f"seed{seed}", TASK, "s3rl", seed, episodes(new_reward, 5),
                 curve={"frames": frames, "train/reward": new_curve})
    result = before_after([before], [after])
    (row,) = result.rows
    assert [(p.before_training_reward, p.after_training_reward) for p in row.pairs] == [
        (80.0, 60.0), (50.0, 40.0)]
    assert row.reward_kept == pytest.approx(30 / 80)
    assert row.kept("training_reward") == pytest.approx(50 / 65)
    (kept,) = [t for t in result.targets if t.kind == "reward_kept"]
    assert not kept.met
    assert kept.value == "0.38 of 80.0 (target >= 0.85); training reward 0.77 of 65.0"


def test_task_targets_and_the_best_feasible_protocol(trees, make_run):
    before, after = trees
    result = before_after([before], [after], task_targets={TASK: (100, 6)})
    bars = {t.name.split()[0]: t for t in result.targets if "mean reward and cost" in t.name}
    assert not bars["sac_lag"].met  # 100 / 6.67: the reward bar is met, the cost bar is not...
    assert "100.00 / 6.67" in bars["sac_lag"].value and bars["s3rl"].value.startswith("40.00")
    # ... while no run has a best-feasible evaluation: nothing to pair under that protocol.
    with pytest.raises(ReportError, match="nothing to compare"):
        before_after([before], [after], "best_feasible")


def test_each_target_names_its_kind_algo_and_task(trees):
    # What docs/update_table1.py groups the targets by (their JSON carries the same fields): per
    # algo one "within" and one "moving" target, then one "reward_kept" per task and algo whose
    # old cost was within the limit (s3rl alone here), one "task" per algo of a named task.
    # ``least`` is the bar as a number: the runs needed (1 of s3rl's one pair, 2 of sac_lag's
    # three as asked), the share of the old reward; none for 'all' and for a pair of bounds.
    before, after = trees
    result = before_after([before], [after], within_target={"sac_lag": 2}, reward_kept=0.9,
                          task_targets={TASK: (100, 6)})
    assert [(t.kind, t.algo, t.task, t.least) for t in result.targets] == [
        ("within", "s3rl", "", 1), ("within", "sac_lag", "", 2),
        ("moving", "s3rl", "", None), ("moving", "sac_lag", "", None),
        ("reward_kept", "s3rl", TASK, 0.9),
        ("task", "s3rl", TASK, None), ("task", "sac_lag", TASK, None),
    ]
    assert {t.kind for t in result.targets} == set(TARGET_KINDS)
    # The names still say the same: the algo first, and the task where it is one task's.
    for target in result.targets:
        assert target.name.startswith(target.algo) and target.task in target.name


def test_a_seed_given_twice_or_under_two_limits_is_refused(trees, make_run, tmp_path):
    before, after = trees
    with pytest.raises(ReportError, match="give each preset's runs once"):
        before_after([before, before], [after])
    other = make_run(tmp_path / "limit/seed10", TASK, "sac_lag", 10, episodes(1, 1),
                     task__cost_limit=25.0)
    with pytest.raises(ReportError, match="one limit"):
        before_after([before / "sac_lag"], [other.parent])


def test_cli_writes_the_page_and_the_json(trees, tmp_path, capsys):
    before, after = trees
    out, record = tmp_path / "ba.md", tmp_path / "ba.json"
    assert main(["before-after", "--before", str(before), "--after", str(after),
                 "--within", "sac_lag=2", "--task-target", f"{TASK}=20,25",
                 "--out", str(out), "--json", str(record)]) == 0
    page = out.read_text()
    assert "| sac_lag: runs within the limit (after; before 1 of 3) | 3 of 3 (target >= 2) | yes |" \
        in page
    assert "- unfinished: SafetyHalfCheetahVelocity-v1 s3rl 20." in page
    assert "- after only: SafetyHalfCheetahVelocity-v1 s3rl 30." in page
    data = json.loads(record.read_text())
    assert [r["within_after"] for r in data["rows"]] == [1, 3]  # s3rl, sac_lag (sorted)
    assert data["unpaired"] == [[TASK, "s3rl", 20, "unfinished"], [TASK, "s3rl", 30, "after only"]]
    # The other way round, seed 30 is on the old side only.
    assert main(["before-after", "--before", str(after), "--after", str(before),
                 "--out", str(out)]) == 0
    assert "- before only: SafetyHalfCheetahVelocity-v1 s3rl 30." in out.read_text()
    assert main(["before-after", "--before", str(before), "--after", str(tmp_path / "none"),
                 "--out", str(out)]) == 2
    assert "is not a directory" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["before-after", "--before", str(before), "--after", str(after), "--out",
              str(out), "--task-target", "bad"])


def test_the_delivered_protocol_reads_a_run_without_a_pick_as_its_last_policy(tmp_path, make_run):
    # Before: no pick (eval.delivery_epochs absent or 0): each run delivered its last policy.
    # After: eval.delivery_epochs=10; final_eval.json's `delivered` is the pick's evaluation.
    before, after = tmp_path / "before", tmp_path / "after"
    make_run(before / "seed10", TASK, "sac_lag", 10, episodes(100, 30))
    make_run(before / "seed20", TASK, "sac_lag", 20, episodes(120, 5), eval__delivery_epochs=0)
    for seed, last, pick in ((10, (90, 12), (95, 6)), (20, (110, 14), (105, 4))):
        run = make_run(after / f"seed{seed}", TASK, "sac_lag", seed, episodes(*last),
                       eval__delivery_epochs=10)
        final = json.loads((run / "final_eval.json").read_text())
        final["delivered"] = {"reward_mean": float(pick[0]), "cost_mean": float(pick[1])}
        (run / "final_eval.json").write_text(json.dumps(final))
    # A run that was to pick (delivery_epochs > 0) but has no pick is not read as its last.
    make_run(before / "seed30", TASK, "sac_lag", 30, episodes(1, 1), eval__delivery_epochs=5)
    make_run(after / "seed30", TASK, "sac_lag", 30, episodes(1, 1), eval__delivery_epochs=10)

    def pairs(protocol):
        (row,) = before_after([before], [after], protocol).rows
        return [(p.seed, p.before_reward, p.before_cost, p.after_reward, p.after_cost)
                for p in row.pairs]

    assert pairs("delivered") == [(10, 100, 30, 95, 6), (20, 120, 5, 105, 4)]
    assert before_after([before], [after], "delivered").unpaired == [(TASK, "sac_lag", 30, "unfinished")]
    assert pairs("last") == [(10, 100, 30, 90, 12), (20, 120, 5, 110, 14), (30, 1, 1, 1, 1)]


def test_runs_over_the_limit_after_say_what_their_files_show(tmp_path, make_run):
    # After (limit 10): seed 10's pick was within the limit on its picking episodes (candidates
    # at costs 4 and 30: 1 of 2 within) but costs 14 on the reported ones; seed 20 kept no
    # policy within (candidates 18, 12: the cheapest picked); seed 30 is within (no row).
    # Training cost: 10 epochs, the last 20% (2 epochs) at 9 and 11 -> 10.0. Episode lengths:
    # seed 10's last policy runs HalfCheetah's full 1000 steps, the others end at 50.
    before, after = tmp_path / "before", tmp_path / "after"
    curve = {"frames": list(range(100, 1100, 100)), "train/cost": [50.0] * 8 + [9.0, 11.0]}
    picks = {10: (14, 9, [(9, 4.0), (10, 30.0)]), 20: (13, 10, [(9, 18.0), (10, 12.0)]),
             30: (3, 10, [(9, 3.0), (10, 2.0)])}
    for seed, (cost, epoch, candidates) in picks.items():
        make_run(before / f"seed{seed}", TASK, "sac_lag", seed, episodes(100, 20))
        last = episodes(100, 20)
        if seed == 10:
            last["lengths"] = [1000, 1000]
        run = make_run(after / f"seed{seed}", TASK, "sac_lag", seed, last,
                       curve=curve, eval__delivery_epochs=2)
        final = json.loads((run / "final_eval.json").read_text())
        final["delivered"] = {"reward_mean": 90.0, "cost_mean": float(cost),
                              "epoch": epoch, "pick_cost_limit": 10.0, "length_mean": 1000.0,
                              "candidates": [{"epoch": e, "frames": 100 * e, "reward": 1.0,
                                              "cost": c} for e, c in candidates]}
        (run / "final_eval.json").write_text(json.dumps(final))
    misses = before_after([before], [after], "delivered").misses
    assert [(m.seed, m.cost, m.training_cost, m.pick_cost, m.candidates_within, m.candidates)
            for m in misses] == [(10, 14, 10.0, 4.0, 1, 2), (20, 13, 10.0, 12.0, 0, 2)]
    assert misses[0].reason.startswith("picked at 4.0 on its picking episodes (1 of 2 within), "
                                       "14.0 on the reported ones")
    assert misses[1].reason.startswith("none of the 2 kept policies was within the limit")
    assert [m.cause for m in misses] == ["pick_reported_over", "pick_none_within"]
    # The last policies (cost 20 each, all over): the training cost only, 10.0 at the limit of
    # 10, within it as a cost of 10 is (0.5 more is over).
    last = before_after([before], [after], "last").misses
    assert [m.seed for m in last] == [10, 20, 30] and last[0].pick_cost is None
    assert last[0].reason == "training cost 10.0 over the last 20% of epochs"
    # Seed 20's episodes end at 50 of HalfCheetah's 1000 steps (the registry's time limit).
    assert (last[1].length, last[1].max_length, last[1].ends_early) == (50.0, 1000, True)
    assert last[1].reason == ("training cost 10.0 over the last 20% of epochs; its episodes end "
                              "early (50 of 1000 steps on average)")
    assert not last[0].ends_early and not misses[0].ends_early
    # A task the registry does not know has no time limit to compare with.
    assert not dataclasses.replace(last[1], max_length=None).ends_early
    assert {m.cause for m in last} == {"training_within"}
    assert dataclasses.replace(last[0], training_cost=10.5).cause == "training_over"
    assert set(MISS_CAUSES) == {"training_within", "training_over", "pick_reported_over",
                                "pick_none_within"}
    out, record = tmp_path / "page.md", tmp_path / "page.json"
    assert main(["before-after", "--before", str(before), "--after", str(after),
                 "--protocol", "delivered", "--out", str(out), "--json", str(record)]) == 0
    assert f"| {TASK} | sac_lag | 20 | 13.0 (10) | none of the 2 kept" in out.read_text()
    saved = json.loads(record.read_text())["misses"]
    assert [(m["seed"], m["candidates_within"]) for m in saved] == [(10, 1), (20, 0)]
    assert saved[1]["reason"] == misses[1].reason
    assert [m["cause"] for m in saved] == ["pick_reported_over", "pick_none_within"]


def test_runs_that_gave_up_their_task_are_counted_and_listed(tmp_path, make_run):
    # Best evaluation rewards in training (eval/reward): 50 at 200 frames for each run but one.
    # After: seed 10 ends at 4.0 (<= 0.1 x 50: stopped), seed 20 at 6.0 (moving), seed 30's
    # evaluations never earned a positive reward (nothing to give up). Before: seed 20 at 5.0
    # (stopped, exactly at the share), the others at 40.
    before, after = tmp_path / "before", tmp_path / "after"
    learned = {"frames": [100, 200, 300], "eval/reward": [10.0, 50.0, 3.0]}
    never = {"frames": [100, 200, 300], "eval/reward": [-5.0, -2.0, 0.0]}
    finals = {10: (40, 4), 20: (5, 6), 30: (40, -10)}
    for seed, (old, new) in finals.items():
        make_run(before / f"seed{seed}", TASK, "sac_lag", seed, episodes(old, 0), curve=learned)
        make_run(after / f"seed{seed}", TASK, "sac_lag", seed, episodes(new, 0),
                 curve=never if seed == 30 else learned)
    result = before_after([before], [after])
    assert [(s.side, s.seed, s.reward, s.best_reward, s.best_frames) for s in result.stops] == [
        ("after", 10, 4.0, 50.0, 200), ("before", 20, 5.0, 50.0, 200)]
    (moving,) = [t for t in result.targets if "still moving" in t.name]
    assert "(after; before 2 of 3)" in moving.name
    assert moving.value == "2 of 3 (target: all)" and not moving.met
    # A looser share: seed 10 (4 > 0.05 x 50) moves, seed 20 before (5 > 2.5) too.
    assert before_after([before], [after], moving_share=0.05).stops == []
    out, record = tmp_path / "page.md", tmp_path / "page.json"
    assert main(["before-after", "--before", str(before), "--after", str(after),
                 "--out", str(out), "--json", str(record)]) == 0
    assert f"| after | {TASK} | sac_lag | 10 | 4.0 | 50.0 (200) |" in out.read_text()
    assert [s["seed"] for s in json.loads(record.read_text())["stops"]] == [10, 20]
