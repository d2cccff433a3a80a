"""The standing benchmarks: what ``make bench`` measures, as one registry.

Each entry of :data:`STANDING` is a function of a size that returns its rows, one number each:
``{"benchmark": name, "case": ..., "value": ..., "unit": ..., **details}``. Two sizes:

- ``"default"``: what ``make bench`` (``python benchmarks/run.py``) runs, minutes in all;
- ``"quick"``: seconds per benchmark, eager, tiny sizes: the smoke test
  (tests/benchmarks/test_harness.py) and ``run.py --quick``. Its numbers measure nothing.

The functions call the measuring functions of the standing scripts (``env_throughput.py``,
``sampler.py``, ``loss_step.py``, ``train_throughput.py``, ``multiseed_throughput.py``) at
sizes of their own. Each script's command line stays the way to take the full measurements
that docs/benchmarks.md reports; the one-off studies are in ``benchmarks/studies/``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
if str(BENCHMARKS) not in sys.path:  # the standing scripts, imported by name
    sys.path.insert(0, str(BENCHMARKS))

SIZES = ("quick", "default")
TASK = "SafetyHalfCheetahVelocity-v1"


@dataclass(frozen=True)
class Benchmark:
    name: str
    what: str  # what is measured, one sentence (run.py --list)
    measure: Callable[[str], list[dict]]  # size -> rows


STANDING: dict[str, Benchmark] = {}


def standing(name: str, what: str):
    """Register ``fn(size) -> rows`` as the standing benchmark ``name``."""

    def register(fn: Callable[[str], list[dict]]) -> Callable[[str], list[dict]]:
        STANDING[name] = Benchmark(name, what, fn)
        return fn

    return register


def row(case: str, value: float, unit: str, **details) -> dict:
    return {"case": case, "value": float(value), "unit": unit, **details}


def _count(n: int) -> str:
    """10000 -> "1e4", 4000 -> "4e3"."""
    mantissa, exponent = f"{n:.0e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def run_benchmark(name: str, size: str = "default") -> list[dict]:
    """The rows of one standing benchmark, measured in this process."""
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}, got {size!r}")
    rows = STANDING[name].measure(size)
    for r in rows:
        r["benchmark"] = name
    return rows


def _threads(count: int) -> None:
    import torch

    torch.set_num_threads(count)


@standing(
    "env_throughput",
    "env steps per second, random actions, one thread: raw Gymnasium, make_env with one env "
    "and with 10 copies in one SyncVectorEnv (make_env's default batching)",
)
def env_throughput(size: str) -> list[dict]:
    from env_throughput import raw_gymnasium, torchrl_env

    _threads(1)
    quick = size == "quick"
    frames, copies = (40, 2) if quick else (4000, 10)
    tasks = [TASK] if quick else [TASK, "SafetyHopperVelocity-v1"]
    rows = []
    for task in tasks:
        details = {"task": task, "frames": frames}
        rows.append(row(f"{task} raw Gymnasium", raw_gymnasium(task, frames), "frames/s",
                        **details))
        rows.append(row(f"{task} make_env 1 env", torchrl_env(task, frames, 1, "serial"),
                        "frames/s", **details))
        rows.append(row(f"{task} make_env {copies} envs sync_vector",
                        torchrl_env(task, frames, copies, "sync_vector"), "frames/s", **details))
    return rows


@standing(
    "sampler",
    "SafeUnsafeSampler's contrastive index draw (3B indices, B = 256 triplets) and full batch "
    "at two buffer sizes, their ratio (target: within 1.5x from 1e4 to 1e6), and one InfoNCE "
    "step; one thread",
)
def sampler(size: str) -> list[dict]:
    from sampler import bench_infonce, bench_size

    _threads(1)
    quick = size == "quick"
    sizes = (1000, 4000) if quick else (10_000, 1_000_000)
    args = argparse.Namespace(
        triplets=16 if quick else 256, unsafe=0.2, calls=5 if quick else 300,
        rounds=1 if quick else 5, threads=1, infonce_threads=[1],
    )
    rows, index = [], {}
    for stored in sizes:
        result = bench_size(stored, args)
        index[stored] = result["contrastive_index"]
        details = {"stored_transitions": stored, "triplets": args.triplets}
        rows.append(row(f"contrastive index draw, {_count(stored)} stored",
                        result["contrastive_index"], "us/call", **details))
        rows.append(row(f"contrastive batch (draw and gather), {_count(stored)} stored",
                        result["contrastive_batch"], "us/call", **details))
        rows.append(row(f"uniform index draw (256), {_count(stored)} stored",
                        result["uniform_index"], "us/call", **details))
    small, large = min(sizes), max(sizes)
    rows.append(row(f"contrastive index draw, {_count(large)} vs {_count(small)} stored",
                    index[large] / index[small], "x"))
    infonce = bench_infonce(args, buffer_size=2000 if quick else 20_000,
                            calls=2 if quick else 50, phase_steps=2 if quick else 50)
    rows.append(row(f"InfoNCE step ({3 * args.triplets} rows, 128x128 encoder, Adam)",
                    infonce["threads_1"]["infonce_step_ms"], "ms/step"))
    return rows


@standing(
    "loss_step",
    "one full gradient step (critics, actor, alpha, soft update) of torchrl's SACLoss and of "
    "SACLagLoss on HalfCheetah shapes (batch 256, 128x128, one cost), eager and compiled, "
    "median process CPU time over interleaved rounds; SAC-Lag vs SAC (target: at most 1.4x)",
)
def loss_step(size: str) -> list[dict]:
    from loss_step import bench

    _threads(1)
    quick = size == "quick"
    configs = [("sac", "eager"), ("sac_lag", "eager")]
    if not quick:
        configs += [("sac", "compile"), ("sac_lag", "compile")]
    result = bench("halfcheetah", configs, steps=2 if quick else 20, rounds=1 if quick else 5)
    names = {"sac": "SACLoss", "sac_lag": "SACLagLoss"}
    rows = []
    for mode, entries in result.items():
        for variant, entry in entries.items():
            rows.append(row(f"{names[variant]} {mode}", entry["cpu_ms"], "ms/step (CPU)",
                            wall_ms=entry["wall_ms"]))
        rows.append(row(f"SACLagLoss vs SACLoss {mode}", entries["sac_lag"]["cpu_ratio_to_sac"],
                        "x"))
    return rows


@standing(
    "train_throughput",
    "the whole S3RL recipe at experiment=paper on HalfCheetah (compiled, its two threads): env "
    "steps per second after the first epoch, evaluation time subtracted (target: at most "
    "0.35 h per 1M steps)",
)
def train_throughput(size: str) -> list[dict]:
    from train_throughput import measure

    if size == "quick":
        result = measure(TASK, 200, compiled=False, threads=1, experiment="tiny")
    else:
        result = measure(TASK, 20_000, compiled=True, threads=2)
    details = {k: result[k] for k in ("mode", "frames_measured", "gradient_steps", "threads")}
    return [
        row(f"S3RL recipe, {result['mode']}", result["env_steps_per_s"], "env steps/s",
            **details),
        row(f"S3RL recipe, {result['mode']}, hours per 1M env steps",
            result["hours_per_1M_steps"], "h"),
    ]


@standing(
    "compute_floor",
    "the matrix products of one SAC-Lag gradient step timed as plain ops (the floor), the best "
    "GEMM rate, and the single-seed recipe's wall time per gradient step at experiment=paper "
    "(compiled, two threads) against that floor (target: at most 2x)",
)
def compute_floor(size: str) -> list[dict]:
    from multiseed_throughput import measure_breakdown, measure_floor

    if size == "quick":
        threads = 1
        floor, rates = measure_floor([1], threads, TASK, calls_per_round=2, rounds=1,
                                     gemm_shapes=((64, 64, 64),))
        recipe = measure_breakdown(TASK, 100, threads, None, 100, compiled=False, warmup=200)
    else:
        threads = 2
        floor, rates = measure_floor([1], threads, TASK)
        recipe = measure_breakdown(TASK, 10_000, threads, None, 10_000, compiled=True)
    (products,) = floor
    products_ms = products["median_wall_ms_products_plain_ops"]
    step_ms = recipe["wall_ms_per_gradient_step"]
    return [
        row("products of one gradient step, plain ops", products_ms, "ms/step",
            matmuls=products["matmul_calls_per_seed_step"],
            gflop=products["gflop_per_seed_step"], threads=threads),
        row("products of one gradient step, plain ops, rate", products["gflops_plain_ops"],
            "GFLOP/s"),
        row("best GEMM rate", rates["best_gemm_gflops"], "GFLOP/s",
            by_shape=rates["gemm_gflops_by_shape"]),
        row(f"single-seed recipe, {recipe['mode']}, per gradient step", step_ms, "ms/step",
            by_part=recipe["wall_ms_per_gradient_step_by_part"], threads=threads),
        row("single-seed recipe vs its products", step_ms / products_ms, "x"),
    ]


@standing(
    "multiseed",
    "several seeds in one process (MultiSeedTrainer, experiment=paper, compiled, two threads): "
    "env steps per second summed over seeds for K = 1 and K = 5, and K = 5's wall time against "
    "K = 1's (target: at most 2x)",
)
def multiseed(size: str) -> list[dict]:
    from multiseed_throughput import measure_recipe

    quick = size == "quick"
    if quick:
        ks, frames, batch, warmup, compiled, threads = (1, 2), 100, 100, 200, False, 1
    else:
        ks, frames, batch, warmup, compiled, threads = (1, 5), 2000, 2000, None, True, 2
    rates = {}
    rows = []
    for k in ks:
        result = measure_recipe(TASK, frames, compiled, threads, k, batch, warmup)
        rates[k] = result["env_steps_per_s_all_seeds"]
        rows.append(row(f"MultiSeedTrainer K={k}, {result['mode']}", rates[k],
                        "env steps/s (all seeds)",
                        cpu_env_steps_per_s=result["env_steps_per_cpu_s_all_seeds"],
                        frames_per_seed=frames, threads=threads))
    one, many = ks
    rows.append(row(f"K={many} wall time vs K={one}", many * rates[one] / rates[many], "x"))
    return rows

