"""What the report's stratified bootstrap costs with rliable's own draw
(``library.get_interval_estimates``: ``np.random.choice`` per task per resample) and with
``report.aggregate.bootstrap``'s (``np.random.randint``, the same draws), on Table 1's shape:
16 tasks x 3 seeds per algo, the cost's probability of improvement of one algo over the other
(32 strata, 2000 resamples, as ``make report``). Process CPU time, the two interleaved over
rounds, so that other jobs on the cores hit both alike; the intervals are checked equal.

    python research/studies/bootstrap_draw_cost.py [--rounds 5] [--reps 2000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from rliable import library

from s3rl_torchrl.report import aggregate as agg

TASKS, SEEDS = 16, 3


def strata() -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    rng = np.random.default_rng(0)
    costs = [{f"task{t:02d}": rng.gamma(2.0, 5.0, SEEDS) for t in range(TASKS)} for _ in "xy"]
    return costs[0], costs[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--reps", type=int, default=agg.DEFAULT_REPS)
    args = parser.parse_args()
    x, y = strata()
    columns = agg._columns(x) + agg._columns(y)

    def func(*cols):  # the report's cost probability of improvement (aggregate.py)
        half = len(cols) // 2
        return np.array([np.mean([agg._improvement(b, a) for a, b in zip(cols[:half],
                                                                          cols[half:])])])

    def rliable_estimate():
        np.random.seed(agg.DEFAULT_SEED)
        points, intervals = library.get_interval_estimates({"s": columns}, func, reps=args.reps)
        return points["s"], intervals["s"][0], intervals["s"][1]

    def ours():
        return agg.bootstrap(func, columns, args.reps, agg.DEFAULT_SEED)

    seconds: dict[str, list[float]] = {"rliable get_interval_estimates": [],
                                       "aggregate.bootstrap": []}
    results = {}
    for _ in range(args.rounds):
        for name, estimate in zip(seconds, (rliable_estimate, ours)):
            start = time.process_time()
            results[name] = estimate()
            seconds[name].append(time.process_time() - start)
    first, second = results.values()
    same = all(np.array_equal(np.ravel(a), np.ravel(b)) for a, b in zip(first, second))
    print(f"{TASKS} tasks x {SEEDS} seeds x 2 algos, {args.reps} resamples, "
          f"{args.rounds} rounds; the same point and interval: {same} "
          f"({float(np.ravel(second[0])[0]):.4f} [{float(np.ravel(second[1])[0]):.4f}, "
          f"{float(np.ravel(second[2])[0]):.4f}])")
    for name, values in seconds.items():
        print(f"{name}: median {statistics.median(values):.2f} s CPU "
              f"(min {min(values):.2f}, max {max(values):.2f})")


if __name__ == "__main__":
    main()
