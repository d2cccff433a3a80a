"""Run the standing benchmarks (harness.py) and print one table: what ``make bench`` does.

    python benchmarks/run.py [NAME ...] [--quick] [--out PATH] [--list]

Every benchmark runs in a fresh process, one after the other (nothing compiled or allocated
by one is seen by the next). The table goes to stdout as Markdown; the rows, the command, the
machine and the load average go to ``benchmarks/results/standing/<date>.json`` (``<date>_2``,
... when that exists) or ``--out``. ``--quick`` runs the tiny sizes of the smoke test in
seconds per benchmark: its numbers measure nothing, so it writes a file only with ``--out``.
A benchmark that fails is reported and the others still run; the exit status is then 1.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _report import RESULTS, write_report
from harness import STANDING, run_benchmark

ROW = "ROW "


def standing_path() -> Path:
    """``benchmarks/results/standing/<date>.json``, or ``<date>_2.json``, ... if it exists."""
    folder, day = RESULTS / "standing", datetime.date.today().isoformat()
    path, n = folder / f"{day}.json", 1
    while path.exists():
        n += 1
        path = folder / f"{day}_{n}.json"
    return path


def child(name: str, size: str) -> None:
    """One benchmark in this (fresh) process: its rows on stdout, one JSON line each."""
    for r in run_benchmark(name, size):
        print(ROW + json.dumps(r), flush=True)


def measure(name: str, size: str) -> tuple[list[dict], float, str | None]:
    """Rows, seconds and error (None) of one benchmark, run in a fresh process."""
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, __file__, "--child", name, "--size", size],
        stdout=subprocess.PIPE, text=True,
    )
    seconds = time.perf_counter() - start
    rows = []
    for line in done.stdout.splitlines():
        if line.startswith(ROW):
            rows.append(json.loads(line[len(ROW):]))
        else:  # what the measuring code printed, kept out of the table
            print(line, file=sys.stderr)
    error = f"exit status {done.returncode}" if done.returncode else None
    return rows, seconds, error


def _number(value: float) -> str:
    if abs(value) >= 100:
        return f"{value:,.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    return f"{value:.3g}"


def table(rows: list[dict]) -> str:
    lines = ["| benchmark | case | value | unit |", "|---|---|---:|---|"]
    lines += [f"| {r['benchmark']} | {r['case']} | {_number(r['value'])} | {r['unit']} |"
              for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"standing benchmarks to run (default: all of {', '.join(STANDING)})")
    parser.add_argument("--quick", action="store_true",
                        help="tiny sizes, seconds per benchmark (a smoke run, not a measurement)")
    parser.add_argument("--out", type=Path, default=None, help="the JSON file of the run")
    parser.add_argument("--list", action="store_true", help="list the standing benchmarks")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--size", default="default", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        child(args.child, args.size)
        return 0
    if args.list:
        for benchmark in STANDING.values():
            print(f"{benchmark.name}: {benchmark.what}")
        return 0
    unknown = [name for name in args.names if name not in STANDING]
    if unknown:
        parser.error(f"unknown benchmark(s) {unknown}; standing: {list(STANDING)}")
    size = "quick" if args.quick else "default"
    load_start = os.getloadavg()
    rows, runs = [], {}
    for name in args.names or list(STANDING):
        print(f"{name} ({size}) ...", file=sys.stderr, flush=True)
        measured, seconds, error = measure(name, size)
        rows += measured
        runs[name] = {"what": STANDING[name].what, "seconds": round(seconds, 1)}
        if error is not None:
            runs[name]["error"] = error
            print(f"{name} failed: {error}", file=sys.stderr, flush=True)
    out = args.out if args.out is not None or args.quick else standing_path()
    if out is not None:
        write_report(out, {
            "size": size,
            "load_average_1_5_15_min": {"start": load_start, "end": os.getloadavg()},
            "benchmarks": runs,
            "rows": rows,
        })
    print(table(rows))
    return 1 if any("error" in r for r in runs.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
