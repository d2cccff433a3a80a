"""The paper's numbers shipped as data, checked by hand against the printed tables."""

from __future__ import annotations

from s3rl_torchrl.report.paper import load_paper_results, paper_results_for


def _value(values, table, method, metric):
    (v,) = [x for x in values if x.table == table and x.method == method and x.metric == metric]
    return v.mean, v.std


def test_table1_values_as_printed():
    values = load_paper_results()
    table1_tasks = {v.task for v in values if v.table == "Table 1"}
    assert len(table1_tasks) == 16  # 6 Bullet Safety Gym + 10 Safety-Gymnasium rows
    cheetah = paper_results_for("SafetyHalfCheetahVelocityGymnasium-v1")
    assert _value(cheetah, "Table 1", "S3RL", "reward") == (2828.95, 50.71)
    assert _value(cheetah, "Table 1", "SAC-LAG", "cost") == (0.30, 1.33)
    assert _value(cheetah, "Table 1", "both", "length") == (1000.0, 0.0)
    ball = paper_results_for("SafetyBallRun-v0")
    assert _value(ball, "Table 1", "SAC-LAG", "reward") == (-411.08, 501.20)
    walker = paper_results_for("SafetyWalker2dVelocityGymnasium-v1")
    assert _value(walker, "Table 1", "both", "length") == (974.65, 31.11)


def test_table2_values_as_printed():
    drone = paper_results_for("SafetyDroneRun-v0")
    assert _value(drone, "Table 2", "S3RL-LAG", "cost") == (0.15, 0.65)
    cheetah = paper_results_for("SafetyHalfCheetahVelocityGymnasium-v1")
    assert _value(cheetah, "Table 2", "S3RL", "reward") == (10024.07, 116.46)
    (nolag,) = [v for v in cheetah if v.table == "Table 2" and v.algo == "s3rl_nolag"
                and v.metric == "reward"]
    assert nolag.setting == "Non-Lag" and nolag.paper_label == "Half Cheetah-v1"


def test_figure3_differences_quoted_in_the_text():
    ant = paper_results_for("SafetyAntVelocity-v1")
    (diff,) = [v for v in ant if v.metric == "safe_occupancy_diff_pp"]
    assert (diff.table, diff.mean) == ("Figure 3", 9.6)  # Section 4.3: "AntVelocity +9.6 pp"
    (ball,) = [v for v in paper_results_for("SafetyBallRun-v0") if v.table == "Figure 3"]
    assert ball.mean == 91.3


def test_our_task_ids_find_the_papers_gymnasium_api_ids():
    ours = paper_results_for("SafetyHalfCheetahVelocity-v1")
    assert ours == paper_results_for("SafetyHalfCheetahVelocityGymnasium-v1") and ours
    assert paper_results_for("SafetyHalfCheetahVelocity-v0") == []  # the paper ran v1 only
    circle = paper_results_for("SafetyPointCircle1-v0")  # the paper's ...Gymnasium-v0 id
    assert _value(circle, "Table 1", "S3RL", "reward") == (37.54, 4.44)
