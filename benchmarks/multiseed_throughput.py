"""Several seeds in one process: env steps/s summed over seeds, K = 1, 2, 5 (10), paper settings.

    python benchmarks/multiseed_throughput.py [--frames 10000] [--ks 1 2 5] [--modes eager compiled]
        [--threads 1] [--task SafetyHalfCheetahVelocity-v1] [--frames-per-batch 10000]
        [--side-by-side 2] [--out benchmarks/results/archive/<date>/multiseed_throughput.json]
    python benchmarks/multiseed_throughput.py --step-only [--ks 1 2 5 10] [--modes eager compiled]
    python benchmarks/multiseed_throughput.py --floor [--ks 1 5] [--threads 2] [--frames 4000]
    python benchmarks/multiseed_throughput.py --breakdown [--ks 1 5] [--threads 2] [--frames 4000]

Whole recipe (default): for each mode, the single-seed recipe (``Trainer``, the baseline) and
the multi-seed recipe (``MultiSeedTrainer``, ``seeds=[...]``) with K seeds, each in a fresh
process (its peak RSS is the memory reported), at ``experiment=paper`` settings. As in
``train_throughput.py`` the clock runs over ``--frames`` frames per seed *after* the 10 000
warm-up frames, evaluation time subtracted; env steps/s are summed over the seeds.
``--frames-per-batch`` (paper: 10 000, also the epoch) shortens the measured stretch on a busy
machine; the update ratio (0.2 gradient steps per frame) and everything else stay the paper's.
``--side-by-side N`` also runs N single-seed recipes at once, one thread each, in N processes
(the usual way to use N cores for N seeds), and sums their env steps/s: the alternative to one
multi-seed process that the multi-seed trainer has to beat.

``--step-only``: the gradient step alone (one batch of 256 per seed, 128x128 networks), the
single-seed joint step against ``StackedSACLag.update`` for each K, and as a lower bound for
K seeds the single-seed step on K x 256 rows (K seeds' FLOPs, one call's overhead), timed in
interleaved rounds in one process (other processes' load hits every case alike), in wall and
in process CPU time.

``--floor``: how low K seeds' gradient steps can go on this CPU. It counts the matrix products
of one single-seed gradient step (each call's shapes and FLOPs, torch's own FLOP formulas),
times those products as plain ops for K seeds (each one K times larger along its batch
dimension, as ``vmap`` over K seeds makes it), and measures the best GEMM rate torch reaches
here (best of three shapes): K seeds' FLOPs at that rate is the floor of their products. It also
runs the K = 1 ``MultiSeedTrainer`` recipe (compiled) and sets that floor against the target
(K seeds in at most 2x the wall time of K = 1): what is left of the budget for everything else
K seeds do, against what K = 1 spends on it.

``--breakdown``: where a compiled ``MultiSeedTrainer`` run's wall time goes, for each K (fresh
process each): collection, storing, sampling and stacking the batches, the batched update, the
seeds' epoch ends (evaluation included), and the rest, over the measured stretch.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import archive_path, interleaved_rounds, recipe_config, write_report

from s3rl_torchrl.trainer import MultiSeedTrainer, Trainer

WARMUP = 10_000


def warmup_frames(batch: int) -> int:
    """Frames before the clock starts: 10 000 random frames, or the first batch if longer
    (``experiment=paper``'s 20 000-frame collects: the warm-up is one random collect)."""
    return max(WARMUP, batch)


def paper_config(
    task: str,
    frames: int,
    compiled: bool,
    threads: int,
    seeds: list[int] | None,
    batch: int,
    warmup: int | None = None,
):
    """``experiment=paper`` in collects of ``batch`` frames, ``frames`` measured frames after
    ``warmup`` random ones (default :func:`warmup_frames`; the harness's quick size passes a
    few hundred)."""
    warmup = warmup_frames(batch) if warmup is None else warmup
    overrides = [
        "experiment=paper",
        f"collector.frames_per_batch={batch}",
        f"collector.frames_per_epoch={batch}",
        f"task={task}",
        f"collector.total_frames={warmup + frames}",
        # experiment=paper's warm-up is one random collect; the clock starts after the warm-up
        # either way, but the docstring's 10 000 random frames are what is measured after.
        f"collector.init_random_frames={warmup}",
        "eval.max_steps=100",  # evaluation is not what is measured: keep it short
        f"compile={str(compiled).lower()}",
        f"threads={threads}",
    ]
    if seeds is not None:
        overrides.append(f"seeds=[{','.join(map(str, seeds))}]")
    cfg = recipe_config(*overrides)
    cfg.eval.final_episodes = 1
    return cfg


def group_seeds(k: int) -> list[int]:
    """The seeds of a k-seed group: 10, 20, ... (the paper's Table 3 uses 10-50)."""
    return [10 * (i + 1) for i in range(k)]


def paper_agents(cfg, count: int, compile_first=None) -> list[tuple]:
    """``count`` (agent, training env) pairs built as the trainer builds them, agent ``i`` from
    seed ``i``; ``compile_first`` compiles the first agent's update (the recipe's own step)."""
    from s3rl_torchrl.trainer.builders import build_agent, build_envs, build_replay_buffer
    from s3rl_torchrl.trainer.loop import seed_everything

    built = []
    for index in range(count):
        seed_everything(index)
        env, _ = build_envs(cfg)
        compile_fn = compile_first if index == 0 else None
        built.append((build_agent(cfg, env, build_replay_buffer(cfg.algo), compile_fn), env))
    return built


def env_rows(cfg, env, rows: int):
    """``rows`` transitions of a short rollout of ``env``, flattened like a replay sample."""
    steps = rows // cfg.collector.num_envs + 1
    return env.rollout(steps).reshape(-1)[:rows]


def measure_recipe(
    task: str,
    frames: int,
    compiled: bool,
    threads: int,
    k: int | None,
    batch: int,
    warmup: int | None = None,
) -> dict:
    """One run; ``k=None``: the single-seed recipe, else ``MultiSeedTrainer`` with k seeds."""
    seeds = None if k is None else group_seeds(k)
    cfg = paper_config(task, frames, compiled, threads, seeds, batch, warmup)
    warmup = cfg.collector.init_random_frames
    marks: dict[int, list[tuple[float, float]]] = {}  # frames -> [(time, eval seconds)]

    def on_epoch_end(trainer, row):
        marks.setdefault(row["frames"], []).append(
            (time.perf_counter(), time.process_time(), row["eval/seconds"])
        )

    with tempfile.TemporaryDirectory() as run_dir:
        start = time.perf_counter()
        if k is None:
            trainer = Trainer(cfg, run_dir, on_epoch_end=on_epoch_end)
            trainer.run()
            grad_steps = trainer.counters.grad_steps
            buffer = trainer.replay_buffer
        else:
            group = MultiSeedTrainer(cfg, run_dir, on_epoch_end=on_epoch_end)
            group.run()
            grad_steps = group.members[0].counters.grad_steps
            buffer = group.members[0].replay_buffer
    # The storage is allocated at full capacity on first write; the RSS only counts the pages
    # written so far (the frames collected), so the full buffer's size is given apart.
    buffer_mb = buffer.storage._storage.bytes() / 2**20
    # From the end of the epoch that closes the warm-up (every seed evaluated; it holds the
    # first batch's gradient steps) to the end of the last one.
    last = max(marks)
    (t0, cpu0, _), (t1, cpu1, _) = marks[warmup][-1], marks[last][-1]
    eval_seconds = sum(e for f in marks if f > warmup for _, _, e in marks[f])
    seconds = t1 - t0 - eval_seconds
    # Process CPU time (one torch thread) is what the work costs; wall time also counts the
    # time other processes held the cores. Evaluation (100 steps) is left in: it is small.
    cpu_seconds = cpu1 - cpu0
    seeds_count = 1 if k is None else k
    frames_measured = (last - warmup) * seeds_count
    return {
        "recipe": "single-seed Trainer" if k is None else "MultiSeedTrainer",
        "mode": "compiled" if compiled else "eager",
        "seeds": seeds_count,
        "frames_measured_all_seeds": frames_measured,
        "seconds": round(seconds, 2),
        "env_steps_per_s_all_seeds": round(frames_measured / seconds, 1),
        "cpu_seconds": round(cpu_seconds, 2),
        "env_steps_per_cpu_s_all_seeds": round(frames_measured / cpu_seconds, 1),
        "gradient_steps_per_seed": grad_steps,
        # In the measured stretch (the warm-up's first batch of steps comes before it).
        "gradient_steps_measured_per_seed": round((last - warmup) * cfg.algo.update_per_step),
        "warmup_seconds_incl_first_compile": round(t0 - start, 2),
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "replay_buffer_mb_at_capacity_per_seed": round(buffer_mb, 1),
        "threads": threads,
        "frames_per_batch": batch,
    }


def measure_steps(ks: list[int], compiled: bool, threads: int, task: str) -> list[dict]:
    """The gradient step alone: single-seed joint step vs StackedSACLag.update, interleaved."""
    import torch

    from s3rl_torchrl.algorithms.stacked import StackedSACLag, draw_noise
    from s3rl_torchrl.trainer.loop import compile_loss

    torch.set_num_threads(threads)
    cfg = paper_config(task, 0, compiled, threads, None, 10_000)
    # Agent 0 is the baseline: built as the single-seed Trainer builds it, so its ``update`` is
    # the recipe's own joint step (compiled like the recipe's when compiled).
    built = paper_agents(cfg, max(ks), compile_loss if compiled else None)
    agents, env = [agent for agent, _ in built], built[-1][1]
    batch = env_rows(cfg, env, cfg.algo.batch_size)
    action_dim = env.action_spec.shape[-1]
    wrap = compile_loss if compiled else None

    single = agents[0]

    def single_step(rows=batch):
        single.update(rows)

    cases = {"single-seed step": single_step}
    # A lower bound for K agents in one step: ONE agent on K x 256 rows does the FLOPs of K
    # agents with the per-call overhead of one (how far batching over seeds can go at best).
    big = env_rows(cfg, env, max(ks) * cfg.algo.batch_size)
    for k in ks:
        if k > 1:
            rows = big[: k * cfg.algo.batch_size]
            cases[f"single-seed step on {k}x256 rows (bound) K={k}"] = lambda b=rows: single_step(b)
    for k in ks:
        # Fresh copies of the agents' losses: a group turns its losses' tensors into views.
        import copy

        group = StackedSACLag(
            [copy.deepcopy(a.loss) for a in agents[:k]],
            cfg.algo.actor_lr,
            cfg.algo.critic_lr,
            cfg.algo.alpha_lr,
            cfg.algo.tau,
            compile_fn=wrap,
        )
        batches = torch.stack([batch] * k)
        noise = torch.stack([draw_noise(cfg.algo.batch_size, action_dim) for _ in range(k)])
        cases[f"StackedSACLag K={k}"] = lambda g=group, b=batches, n=noise: g.update(b, n)
    wall = interleaved_rounds(cases, calls=20, rounds=7, warmup=5)
    # The same, in process CPU time: what the step costs, whatever else holds the cores.
    cpu = interleaved_rounds(cases, calls=20, rounds=7, warmup=0, clock=time.process_time)
    rows = []
    median = statistics.median
    base_wall, base_cpu = median(wall["single-seed step"]), median(cpu["single-seed step"])
    for name in cases:
        seeds = int(name.split("K=")[1]) if "K=" in name else 1
        rows.append(
            {
                "case": name,
                "mode": "compiled" if compiled else "eager",
                "seeds": seeds,
                "median_wall_ms_per_step": round(median(wall[name]) / 1e3, 3),
                "min_wall_ms_per_step": round(min(wall[name]) / 1e3, 3),
                "median_cpu_ms_per_step": round(median(cpu[name]) / 1e3, 3),
                "cpu_vs_single_seed_step": round(median(cpu[name]) / base_cpu, 2),
                "seed_steps_per_cpu_s_vs_single": round(seeds * base_cpu / median(cpu[name]), 2),
                "wall_vs_single_seed_step": round(median(wall[name]) / base_wall, 2),
                "threads": threads,
            }
        )
    return rows


# The parts of a multi-seed run --breakdown reports; "noise and stacking" is the gradient
# step's own work besides sampling, the update and what follows it (drawing each seed's noise,
# stacking the seeds' batches), "rest" what no part holds (the loop, progress, counters).
BREAKDOWN_PARTS = ("collect", "store", "sample", "noise and stacking", "update", "after update",
                   "epoch end", "rest")


def measure_breakdown(task: str, frames: int, threads: int, k: int | None, batch: int,
                      compiled: bool = True, warmup: int | None = None) -> dict:
    """One ``MultiSeedTrainer`` run with k seeds (``k=None``: the single-seed ``Trainer``, the
    recipe without ``seeds``), its measured stretch split in parts (wall seconds), by wrapping
    the trainer's methods in timers."""
    cfg = paper_config(task, frames, compiled, threads, None if k is None else group_seeds(k),
                       batch, warmup)
    warmup = cfg.collector.init_random_frames
    spent = dict.fromkeys([*BREAKDOWN_PARTS, "gradient step"], 0.0)
    start: dict[str, float] = {}

    def timed(fn, part):
        def wrapper(*args, **kwargs):
            begin = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[part] += time.perf_counter() - begin
        return wrapper

    def timed_iterator(iterator_fn):
        def iterator():
            inner = iterator_fn()
            while True:
                begin = time.perf_counter()
                item = next(inner, None)
                spent["collect"] += time.perf_counter() - begin
                if item is None:
                    return
                yield item
        return iterator

    with tempfile.TemporaryDirectory() as run_dir:
        if k is None:
            trainer = Trainer(cfg, run_dir)
            members = [trainer]
        else:
            trainer = MultiSeedTrainer(cfg, run_dir)
            members = trainer.members
        last = members[-1]
        for member in members:
            # The sampling call every family's update uses (ReplayUpdates.sample).
            member.replay_buffer.sample = timed(member.replay_buffer.sample, "sample")
            member._store = timed(member._store, "store")
            member._after_gradient_step = timed(member._after_gradient_step, "after update")

            def make_collector(make=member._make_collector):
                collector = make()
                collector.iterator = timed_iterator(collector.iterator)
                return collector

            member._make_collector = make_collector
            end_epoch = timed(member._end_epoch, "epoch end")

            def end_epoch_and_mark(member=member, end_epoch=end_epoch):
                end_epoch()
                # The clock starts when the last seed has closed the warm-up's epoch.
                if member is last and member.counters.frames == warmup:
                    start.update(spent, clock=time.perf_counter())

            member._end_epoch = end_epoch_and_mark
        if k is None:
            trainer._update = timed(trainer._update, "update")
        else:
            trainer.stacked.update = timed(trainer.stacked.update, "update")
        trainer._gradient_step = timed(trainer._gradient_step, "gradient step")
        trainer.run()
        total = time.perf_counter() - start["clock"]
    parts = {part: spent[part] - start[part] for part in spent}
    gradient_step = parts.pop("gradient step")
    parts["noise and stacking"] = gradient_step - sum(
        parts[part] for part in ("sample", "update", "after update"))
    parts["rest"] = total - sum(value for part, value in parts.items() if part != "rest")
    measured = cfg.collector.total_frames - warmup
    steps = round(measured * cfg.algo.update_per_step)
    return {
        "recipe": "single-seed Trainer" if k is None else "MultiSeedTrainer",
        "mode": "compiled" if compiled else "eager",
        "seeds": 1 if k is None else k,
        "threads": threads,
        "frames_per_batch": batch,
        "frames_measured_per_seed": measured,
        "gradient_steps_measured": steps,
        "wall_seconds": round(total, 2),
        "wall_ms_per_gradient_step": round(total / steps * 1e3, 3),
        "wall_seconds_by_part": {part: round(parts[part], 2) for part in BREAKDOWN_PARTS},
        "wall_ms_per_gradient_step_by_part": {
            part: round(parts[part] / steps * 1e3, 2) for part in BREAKDOWN_PARTS
        },
    }


def record_matmuls(task: str, threads: int) -> tuple[list[dict], float]:
    """The matrix products of one single-seed gradient step at paper settings (eager): per
    call the op and operand shapes, and the step's total FLOPs (torch's formulas)."""
    import torch
    from torch.utils._python_dispatch import TorchDispatchMode
    from torch.utils.flop_counter import flop_registry

    torch.set_num_threads(threads)
    cfg = paper_config(task, 0, False, threads, None, 10_000)
    [(agent, env)] = paper_agents(cfg, 1)
    batch = env_rows(cfg, env, cfg.algo.batch_size)
    matmuls = {"mm", "addmm", "bmm", "baddbmm"}

    class Recorder(TorchDispatchMode):
        def __init__(self):
            super().__init__()
            self.calls, self.flops = [], 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            kwargs = kwargs or {}
            out = func(*args, **kwargs)
            name = func._overloadpacket.__name__
            count = flop_registry.get(func._overloadpacket)
            if count is not None:
                self.flops += count(*args, out_val=out, **kwargs)
            if name in matmuls:
                left, right = (args[1], args[2]) if name.startswith(("add", "badd")) else args[:2]
                self.calls.append({"op": name, "left": list(left.shape),
                                   "right": list(right.shape)})
            return out

    agent.update(batch)  # lazy initialisations happen outside the count
    recorder = Recorder()
    with recorder:
        agent.update(batch)
    return recorder.calls, recorder.flops


def gemm_rate(shape: tuple[int, int, int], threads: int, rounds: int = 7) -> float:
    """GFLOP/s of one ``[m, k] x [k, n]`` product, median of ``rounds`` rounds."""
    import torch

    torch.set_num_threads(threads)
    m, k, n = shape
    a, b = torch.randn(m, k), torch.randn(k, n)
    calls = max(5, int(2e9 / (2 * m * k * n)))  # ~2 GFLOP per round
    times = interleaved_rounds({"gemm": lambda: a @ b}, calls=calls, rounds=rounds,
                               warmup=3)["gemm"]
    return 2 * m * k * n / (statistics.median(times) / 1e6) / 1e9


# The three shapes whose best GEMM rate is the floor's rate: the step's main product, five
# times it, a large square.
GEMM_SHAPES = ((256, 128, 128), (1280, 128, 128), (2048, 2048, 2048))


def measure_floor(ks: list[int], threads: int, task: str, calls_per_round: int = 20,
                  rounds: int = 7, gemm_shapes=GEMM_SHAPES) -> tuple[list[dict], dict]:
    """The step's matrix products for K seeds: counted, timed as plain ops at their own shapes
    (each K times larger along its batch dimension, as ``vmap`` makes them), and the best GEMM
    rate torch reaches here over three shapes (the step's main one, five times it, a large
    square), the floor's rate: the step's skinnier products only run slower."""
    import torch

    calls, flops = record_matmuls(task, threads)
    cases = {}
    for k in ks:
        operands = []
        for call in calls:
            left, right = call["left"], call["right"]
            if len(left) == 2:  # mm / addmm: one product per seed (bmm under vmap)
                shapes = ([k, *left], [k, *right]) if k > 1 else (left, right)
            else:  # bmm / baddbmm (the critic ensembles): k times the batch
                shapes = ([k * left[0], *left[1:]], [k * right[0], *right[1:]])
            operands.append((torch.randn(shapes[0]), torch.randn(shapes[1])))

        def products(operands=operands):
            for a, b in operands:
                torch.matmul(a, b)

        cases[f"K={k}"] = products
    wall = interleaved_rounds(cases, calls=calls_per_round, rounds=rounds, warmup=5)
    peak = {f"{m}x{k}x{n}": round(gemm_rate((m, k, n), threads, rounds), 1)
            for m, k, n in gemm_shapes}
    best = max(peak.values())
    rows = []
    for k in ks:
        ms = statistics.median(wall[f"K={k}"]) / 1e3
        rows.append({
            "case": f"matrix products of {k} seed-steps, plain ops",
            "seeds": k,
            "matmul_calls_per_seed_step": len(calls),
            "gflop_per_seed_step": round(flops / 1e9, 4),
            "median_wall_ms_products_plain_ops": round(ms, 3),
            "gflops_plain_ops": round(k * flops / 1e9 / (ms / 1e3), 1),
            "ms_products_at_best_gemm_rate": round(k * flops / 1e9 / best * 1e3, 3),
            "threads": threads,
        })
    return rows, {"gemm_gflops_by_shape": peak, "best_gemm_gflops": best}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--ks", type=int, nargs="*", default=[1, 2, 5])
    parser.add_argument("--modes", nargs="*", default=["eager", "compiled"])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--frames-per-batch", type=int, default=10_000)
    parser.add_argument("--step-only", action="store_true")
    parser.add_argument("--floor", action="store_true")
    parser.add_argument("--breakdown", action="store_true")
    parser.add_argument("--single", action="store_true",
                        help="--breakdown: the single-seed Trainer instead of K seeds")
    parser.add_argument(
        "--side-by-side", type=int, default=0, metavar="N",
        help="also run N single-seed recipes at once, one thread each",
    )
    parser.add_argument("--one", nargs=2, metavar=("MODE", "K"), help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.one is not None:  # a child process: one run, its row on stdout
        mode, k = args.one
        if mode.startswith("breakdown"):  # breakdown (compiled) or breakdown-eager
            row = measure_breakdown(args.task, args.frames, args.threads,
                                    None if k == "single" else int(k), args.frames_per_batch,
                                    compiled=mode != "breakdown-eager")
            print("ROW " + json.dumps(row), flush=True)
            return
        k = None if k == "single" else int(k)
        compiled = mode == "compiled"
        row = measure_recipe(args.task, args.frames, compiled, args.threads, k, args.frames_per_batch)
        print("ROW " + json.dumps(row), flush=True)
        return
    rows = []
    if args.step_only:
        for mode in args.modes:
            for row in measure_steps(args.ks, mode == "compiled", args.threads, args.task):
                print(json.dumps(row), flush=True)
                rows.append(row)
        out = args.out or archive_path("multiseed_step")
        write_report(out, {"rows": rows})
        return
    def child(mode: str, k: str, threads: int) -> list[str]:
        return [sys.executable, __file__, "--one", mode, k, "--frames", str(args.frames),
                "--threads", str(threads), "--task", args.task,
                "--frames-per-batch", str(args.frames_per_batch)]

    def row_of(stdout: str) -> dict:
        return json.loads(next(line for line in stdout.splitlines() if line.startswith("ROW "))[4:])

    if args.breakdown:
        rows = []
        for k in ["single"] if args.single else args.ks:
            row = row_of(subprocess.run(child("breakdown", str(k), args.threads),
                                        capture_output=True, text=True, check=True).stdout)
            print(json.dumps(row), flush=True)
            rows.append(row)
        out = args.out or archive_path("multiseed_breakdown")
        write_report(out, {"rows": rows})
        return
    if args.floor:
        rows, rates = measure_floor(args.ks, args.threads, args.task)
        # The K = 1 recipes, whole run after the warm-up (collection, storing, sampling, the
        # update, the target update, epoch ends with a 100-step evaluation), split in parts.
        recipes = {}
        for mode in args.modes:
            for k in ("single", "1"):
                kind = "breakdown" if mode == "compiled" else "breakdown-eager"
                recipe = row_of(subprocess.run(child(kind, k, args.threads),
                                               capture_output=True, text=True, check=True).stdout)
                recipes[f"{'single_seed_trainer' if k == 'single' else 'multiseed_k1'}_{mode}"] = recipe
        plain = {row["seeds"]: row["median_wall_ms_products_plain_ops"] for row in rows}
        # The floor of the products: the step's FLOPs at the best GEMM rate this CPU reaches.
        products = {row["seeds"]: row["ms_products_at_best_gemm_rate"] for row in rows}
        summary = {**rates, "k1_products_plain_ops_ms": plain.get(1)}
        for name, recipe in recipes.items():
            ms = recipe["wall_ms_per_gradient_step"]
            summary[name] = {
                "wall_ms_per_gradient_step": ms,
                # The target: at most 2x the products timed as plain ops.
                "ratio_to_products_plain_ops": round(ms / plain[1], 2) if 1 in plain else None,
                "ratio_to_products_at_best_gemm_rate": (
                    round(ms / products[1], 2) if 1 in products else None),
                "wall_ms_per_gradient_step_by_part": recipe["wall_ms_per_gradient_step_by_part"],
            }
        k1_ms = recipes.get("multiseed_k1_compiled", {}).get("wall_ms_per_gradient_step",
                                                             float("nan"))
        for k in args.ks:
            if k > 1:
                summary[f"k{k}_budget_ms_per_step_at_2x_k1"] = round(2 * k1_ms, 3)
                summary[f"k{k}_budget_ms_left_besides_products_floor"] = round(
                    2 * k1_ms - products[k], 3)
        for row in rows:
            print(json.dumps(row), flush=True)
        print(json.dumps(summary), flush=True)
        out = args.out or archive_path("multiseed_floor")
        write_report(out, {"rows": rows, "summary": summary})
        return

    for mode in args.modes:
        for k in ["single", *map(str, args.ks)]:
            out = subprocess.run(child(mode, k, args.threads), capture_output=True, text=True,
                                 check=True).stdout
            row = row_of(out)
            print(json.dumps(row), flush=True)
            rows.append(row)
        if args.side_by_side:
            # The same seed in each process: what is measured is the cost, not the trajectory.
            procs = [subprocess.Popen(child(mode, "single", 1), stdout=subprocess.PIPE, text=True)
                     for _ in range(args.side_by_side)]
            runs = []
            for proc in procs:
                out, _ = proc.communicate()
                if proc.returncode:
                    raise subprocess.CalledProcessError(proc.returncode, proc.args)
                runs.append(row_of(out))
            row = {
                "recipe": f"{args.side_by_side} single-seed Trainers side by side",
                "mode": runs[0]["mode"],
                "seeds": args.side_by_side,
                "frames_measured_all_seeds": sum(r["frames_measured_all_seeds"] for r in runs),
                # Each process times its own stretch; they run at once, so the rates add up.
                "env_steps_per_s_all_seeds": round(
                    sum(r["env_steps_per_s_all_seeds"] for r in runs), 1
                ),
                "env_steps_per_cpu_s_all_seeds": round(
                    sum(r["frames_measured_all_seeds"] for r in runs)
                    / sum(r["cpu_seconds"] for r in runs), 1
                ),
                "seconds_per_process": [r["seconds"] for r in runs],
                "peak_rss_mb_per_process": [r["peak_rss_mb"] for r in runs],
                "threads": 1,
                "frames_per_batch": args.frames_per_batch,
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
    out = args.out or archive_path("multiseed_throughput")
    write_report(out, {"rows": rows})


if __name__ == "__main__":
    main()
