"""Several seeds in one process: env steps/s summed over seeds, K = 1, 2, 5 (10), paper settings.

    python benchmarks/multiseed_throughput.py [--frames 10000] [--ks 1 2 5] [--modes eager compiled]
        [--threads 1] [--task SafetyHalfCheetahVelocity-v1] [--frames-per-batch 10000]
        [--side-by-side 2] [--out benchmarks/results/multiseed_throughput.json]
    python benchmarks/multiseed_throughput.py --step-only [--ks 1 2 5 10] [--modes eager compiled]

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
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import interleaved_rounds, write_report
from hydra import compose, initialize_config_dir

from s3rl_torchrl.trainer import MultiSeedTrainer, Trainer, register_configs, validate

CONFIG_DIR = str(Path(__file__).resolve().parents[1] / "configs")
WARMUP = 10_000


def paper_config(
    task: str, frames: int, compiled: bool, threads: int, seeds: list[int] | None, batch: int
):
    register_configs()
    overrides = [
        "experiment=paper",
        f"collector.frames_per_batch={batch}",
        f"collector.frames_per_epoch={batch}",
        f"task={task}",
        f"collector.total_frames={WARMUP + frames}",
        # experiment=paper's warm-up is one random collect; the clock starts at WARMUP frames
        # either way, but the docstring's 10 000 random frames are what is measured after.
        f"collector.init_random_frames={WARMUP}",
        "eval.episodes=1",
        "eval.max_steps=100",  # evaluation is not what is measured: keep it short
        "eval.random_baseline=false",
        "logger=none",
        "logger.progress_bar=false",
        f"compile={str(compiled).lower()}",
        f"threads={threads}",
        "save_interval=1000",
    ]
    if seeds is not None:
        overrides.append(f"seeds=[{','.join(map(str, seeds))}]")
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = validate(compose(config_name="train", overrides=overrides))
    cfg.eval.final_episodes = 1
    return cfg


def measure_recipe(
    task: str, frames: int, compiled: bool, threads: int, k: int | None, batch: int
) -> dict:
    """One run; ``k=None``: the single-seed recipe, else ``MultiSeedTrainer`` with k seeds."""
    seeds = None if k is None else [10 * (i + 1) for i in range(k)]
    cfg = paper_config(task, frames, compiled, threads, seeds, batch)
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
    (t0, cpu0, _), (t1, cpu1, _) = marks[WARMUP][-1], marks[last][-1]
    eval_seconds = sum(e for f in marks if f > WARMUP for _, _, e in marks[f])
    seconds = t1 - t0 - eval_seconds
    # Process CPU time (one torch thread) is what the work costs; wall time also counts the
    # time other processes held the cores. Evaluation (100 steps) is left in: it is small.
    cpu_seconds = cpu1 - cpu0
    seeds_count = 1 if k is None else k
    frames_measured = (last - WARMUP) * seeds_count
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
        "warmup_seconds_incl_first_compile": round(t0 - start, 2),
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "replay_buffer_mb_at_capacity_per_seed": round(buffer_mb, 1),
        "threads": threads,
        "frames_per_batch": batch,
    }


def measure_steps(ks: list[int], compiled: bool, threads: int, task: str) -> list[dict]:
    """The gradient step alone: single-seed joint step vs StackedSACLag.update, interleaved."""
    import torch

    from s3rl_torchrl.objectives.stacked import StackedSACLag, draw_noise
    from s3rl_torchrl.trainer.builders import build_agent, build_envs, build_replay_buffer
    from s3rl_torchrl.trainer.loop import compile_loss, seed_everything

    torch.set_num_threads(threads)
    cfg = paper_config(task, 0, compiled, threads, None, 10_000)
    agents = []
    for k in range(max(ks)):
        seed_everything(k)
        env, _ = build_envs(cfg)
        # Agent 0 is the baseline: built as the single-seed Trainer builds it, so its
        # ``update`` is the recipe's own joint step (compiled like the recipe's when compiled).
        compile_fn = compile_loss if compiled and k == 0 else None
        agents.append(build_agent(cfg, env, build_replay_buffer(cfg.algo), compile_fn))
    data = env.rollout(cfg.algo.batch_size // cfg.collector.num_envs + 1).reshape(-1)
    batch = data[: cfg.algo.batch_size]
    action_dim = env.action_spec.shape[-1]
    wrap = compile_loss if compiled else None

    single = agents[0]

    def single_step(rows=batch):
        single.update(rows)

    cases = {"single-seed step": single_step}
    # A lower bound for K agents in one step: ONE agent on K x 256 rows does the FLOPs of K
    # agents with the per-call overhead of one (how far batching over seeds can go at best).
    big = env.rollout(max(ks) * cfg.algo.batch_size // cfg.collector.num_envs + 1).reshape(-1)
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

    def median(values):
        return sorted(values)[len(values) // 2]

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--ks", type=int, nargs="*", default=[1, 2, 5])
    parser.add_argument("--modes", nargs="*", default=["eager", "compiled"])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--task", default="SafetyHalfCheetahVelocity-v1")
    parser.add_argument("--frames-per-batch", type=int, default=10_000)
    parser.add_argument("--step-only", action="store_true")
    parser.add_argument(
        "--side-by-side", type=int, default=0, metavar="N",
        help="also run N single-seed recipes at once, one thread each",
    )
    parser.add_argument("--one", nargs=2, metavar=("MODE", "K"), help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.one is not None:  # a child process: one run, its row on stdout
        mode, k = args.one
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
        out = args.out or Path("benchmarks/results/multiseed_step.json")
        write_report(out, {"rows": rows})
        return
    def child(mode: str, k: str, threads: int) -> list[str]:
        return [sys.executable, __file__, "--one", mode, k, "--frames", str(args.frames),
                "--threads", str(threads), "--task", args.task,
                "--frames-per-batch", str(args.frames_per_batch)]

    def row_of(stdout: str) -> dict:
        return json.loads(next(line for line in stdout.splitlines() if line.startswith("ROW "))[4:])

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
    out = args.out or Path("benchmarks/results/multiseed_throughput.json")
    write_report(out, {"rows": rows})


if __name__ == "__main__":
    main()
