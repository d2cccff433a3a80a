"""research/delivered_policy/delivery_rules.py (issue 60's third round): its jobs are valid runs
on seeds 1 and 2 only, its rules read a run's final_eval.json as stated by hand, and its choice
follows the note's rule on hand-made tallies."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import compose_train
from tests.research.test_delivered_selection import _script


@pytest.fixture(scope="module")
def rules():
    return _script("delivery_rules")


def test_the_jobs_are_valid_runs_on_the_selection_seeds(rules, tmp_path):
    from s3rl_torchrl.trainer import validate

    jobs = list(rules.jobs(tmp_path))
    assert len(jobs) == 30 and len({run_dir for run_dir, _ in jobs}) == 30
    first, second = jobs[:15], jobs[15:]
    # Seed 2's job of each group is seed 1's but for the seed and the directory.
    for (_, one), (_, two) in zip(first, second, strict=True):
        assert [o for o in one if o != "seed=1" and not o.startswith("hydra.")] == [
            o for o in two if o != "seed=2" and not o.startswith("hydra.")
        ]
    for _, overrides in first:
        cfg = validate(compose_train(*[o for o in overrides if not o.startswith("hydra.")]))
        assert cfg.seed == 1  # never a reported seed (10, 20, 30)
        assert cfg.collector.total_frames == 1_000_000
        assert cfg.algo.lagrangian_target == 0.7 and cfg.eval.delivery_epochs == 10
        assert cfg.eval.delivery_report_all and list(cfg.eval.ema_horizons) == [2000, 10000]


def final(candidates):
    return {
        "reward_mean": 50.0, "cost_mean": 12.0,
        "delivered": {"reward_mean": 61.0, "cost_mean": 9.0, "pick_cost_limit": 10.0,
                      "candidates": candidates},
        "ema2000": {"reward_mean": 55.0, "cost_mean": 4.0},
    }


def candidate(reward, cost, report_reward, report_cost):
    return {"reward": reward, "cost": cost, "report_reward": report_reward,
            "report_cost": report_cost}


def test_each_rule_delivers_what_the_note_says(rules):
    run = final([
        candidate(60, 9.0, 58, 14.0),  # within 10, not within 7
        candidate(40, 6.0, 41, 5.0),  # within 7 (and not 5)
        candidate(30, 6.5, 29, 2.0),  # within 7, less reward
    ])
    assert rules.delivered(run, "last", 10.0) == (50.0, 12.0)
    assert rules.delivered(run, "pick1", 10.0) == (61.0, 9.0)  # the run's own pick, as it reported it
    assert rules.delivered(run, "pick0.7", 10.0) == (41, 5.0)  # the most reward at cost <= 7
    # None at cost <= 5: the cheapest (the later on a tie), on its reporting episodes.
    assert rules.delivered(run, "pick0.5", 10.0) == (41, 5.0)
    tie = final([candidate(10, 6.0, 1, 1.0), candidate(20, 6.0, 2, 2.0)])
    assert rules.delivered(tie, "pick0.5", 10.0) == (2, 2.0)
    assert rules.delivered(run, "ema2000", 10.0) == (55.0, 4.0)
    assert rules.delivered(run, "ema10000", 10.0) is None  # a run without that average


def tally(within: int, ratio: float) -> dict:
    return {"within": within, "runs": 30, "ratios": [ratio]}


def test_the_choice_follows_the_note(rules):
    # The most runs within; the preset's pick stays unless another keeps 2 more.
    assert rules.choice({"pick1": tally(27, 0.95), "ema10000": tally(28, 0.97)}).startswith(
        "The rule's choice: pick1, the preset's pick, kept (ema10000 keeps 28 of 30"
    )
    assert rules.choice({"pick1": tally(27, 0.95), "ema10000": tally(29, 0.90)}).startswith(
        "The rule's choice: ema10000 (29 of 30"
    )
    # A tie goes to the higher reward ratio; a ratio below 0.85 is passed over.
    assert rules.choice({"pick1": tally(25, 0.95), "pick0.5": tally(29, 0.84),
                         "pick0.7": tally(28, 0.90), "ema2000": tally(28, 0.92)}).startswith(
        "The rule's choice: ema2000 (28 of 30"
    )
    assert rules.choice({"last": tally(30, 0.5)}).startswith("The rule's choice: none")


def test_the_committed_table_is_the_exported_runs_table(rules):
    # research/delivered_policy/delivery_rules.md is what `summarise` makes of the exported runs;
    # until all 30 are in, its last line says so instead of a choice.
    root = Path(__file__).resolve().parents[2]
    committed = (root / "research" / "delivered_policy" / "delivery_rules.md").read_text()
    assert committed == rules.summarise(root / "research" / "results" / "delivery_rules")
