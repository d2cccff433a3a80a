"""Cost of ``SafeUnsafeSampler`` against the number of stored transitions, and of one InfoNCE step.

    python benchmarks/sampler.py [--sizes 10000 100000 1000000] [--triplets 256] \
        [--unsafe 0.2] [--calls 300] [--rounds 5] [--threads 1] [--infonce-threads 1 2] \
        [--out benchmarks/results/archive/<date>/sampler.json]

For each buffer size N a ``TensorDictReplayBuffer(LazyTensorStorage(N), SafeUnsafeSampler())``
is filled with N HalfCheetah-shaped transitions (observation 17, action 6, reward, cost, flags;
a fraction ``--unsafe`` labelled unsafe, i.i.d.), then, per call, in microseconds:

- ``contrastive_index``: ``sampler.sample(storage, 3B)`` of the contrastive view (index draw
  only, the part whose cost could grow with N);
- ``contrastive_batch``: ``view.sample()``, the index draw plus gathering the 3B rows;
- ``uniform_index`` / ``stratified_index``: ordinary 256-batches (uniform; 25 % unsafe);
- ``extend_1000``: ``rb.extend`` of 1000 transitions into the full ring buffer (overwrites), with
  ``SafeUnsafeSampler`` and, for reference, torchrl's ``RandomSampler``.

Each size is measured in ``--rounds`` rounds of ``--calls`` calls and the median over rounds of
the per-round median is reported, to damp load from other processes (the machine is shared).
Last, one InfoNCE step (``SafetyInfoNCELoss`` forward on 3B rows, backward, Adam step) on the
default 128x128 policy encoder and one ``ContrastivePhase.run()`` of 50 steps are timed, with 1
and 2 torch threads. On a busy 2-core machine two threads can be much slower than one: a parallel
op waits for a thread that another process has descheduled. The sampler runs with one thread.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import torch
from _report import archive_path, write_report
from tensordict import TensorDict
from torchrl.data import Bounded, LazyTensorStorage, RandomSampler, TensorDictReplayBuffer

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder
from s3rl_torchrl.objectives import SafetyInfoNCELoss
from s3rl_torchrl.trainer import ContrastivePhase

OBS_DIM, ACT_DIM = 17, 6


def transitions(n: int, unsafe_fraction: float, generator: torch.Generator) -> TensorDict:
    cost = (torch.rand(n, 1, generator=generator) < unsafe_fraction).float()
    return TensorDict(
        {
            "observation": torch.randn(n, OBS_DIM, generator=generator),
            "action": torch.rand(n, ACT_DIM, generator=generator) * 2 - 1,
            "next": {
                "observation": torch.randn(n, OBS_DIM, generator=generator),
                "reward": torch.randn(n, 1, generator=generator),
                "cost": cost,
                "safe": cost == 0,
                "done": torch.zeros(n, 1, dtype=torch.bool),
                "terminated": torch.zeros(n, 1, dtype=torch.bool),
                "truncated": torch.zeros(n, 1, dtype=torch.bool),
            },
        },
        batch_size=[n],
    )


def per_call_us(fn, calls: int) -> float:
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e6


def filled_buffer(size: int, unsafe_fraction: float, sampler) -> TensorDictReplayBuffer:
    generator = torch.Generator().manual_seed(0)
    rb = TensorDictReplayBuffer(
        storage=LazyTensorStorage(size),
        sampler=sampler,
        generator=torch.Generator().manual_seed(1),
    )
    chunk = min(size, 100_000)
    for start in range(0, size, chunk):
        rb.extend(transitions(min(chunk, size - start), unsafe_fraction, generator))
    return rb


def bench_size(size: int, args) -> dict:
    rb = filled_buffer(size, args.unsafe, SafeUnsafeSampler())
    baseline = filled_buffer(size, args.unsafe, RandomSampler())
    view = SafeUnsafeSampler.contrastive_view(rb, args.triplets)
    stratified = SafeUnsafeSampler.view(rb, 256, unsafe_fraction=0.25).sampler
    storage, batch = rb.storage, 3 * args.triplets
    write = transitions(1000, args.unsafe, torch.Generator().manual_seed(2))
    cases = {
        "contrastive_index": lambda: view.sampler.sample(storage, batch),
        "contrastive_batch": view.sample,
        "uniform_index": lambda: rb.sampler.sample(storage, 256),
        "stratified_index": lambda: stratified.sample(storage, 256),
        "extend_1000_safe_unsafe_sampler": lambda: rb.extend(write),
        "extend_1000_random_sampler": lambda: baseline.extend(write),
    }
    for fn in cases.values():  # warm-up
        for _ in range(10):
            fn()
    rounds = {name: [] for name in cases}
    for _ in range(args.rounds):
        for name, fn in cases.items():
            calls = args.calls if not name.startswith("extend") else max(args.calls // 10, 10)
            rounds[name].append(per_call_us(fn, calls))
    result = {name: statistics.median(values) for name, values in rounds.items()}
    result["num_safe"], result["num_unsafe"] = rb.sampler.num_safe, rb.sampler.num_unsafe
    return result


def bench_infonce(args, buffer_size: int = 20_000, calls: int = 50, phase_steps: int = 50) -> dict:
    """One InfoNCE step (``calls`` per round) and one contrastive phase of ``phase_steps``
    steps, on a buffer of ``buffer_size`` transitions, per thread count of ``--infonce-threads``."""
    torch.manual_seed(0)
    spec = Bounded(-torch.ones(ACT_DIM), torch.ones(ACT_DIM), shape=(ACT_DIM,))
    actor = build_s3rl_actor(OBS_DIM, spec)
    rb = filled_buffer(buffer_size, args.unsafe, SafeUnsafeSampler())
    view = SafeUnsafeSampler.contrastive_view(rb, args.triplets)
    loss = SafetyInfoNCELoss(get_policy_encoder(actor))
    optimizer = torch.optim.Adam(loss.encoder_parameters(), lr=5e-4)
    fixed = view.sample()

    def step():
        out = loss(fixed)
        optimizer.zero_grad()
        out["loss_infonce"].backward()
        optimizer.step()

    phase = ContrastivePhase(loss, view, 5e-4, num_steps=phase_steps)
    result = {"encoder_hidden": [128, 128], "rows_per_step": 3 * args.triplets}
    for threads in args.infonce_threads:
        torch.set_num_threads(threads)
        for _ in range(5):
            step()
        step_ms = statistics.median(per_call_us(step, calls) for _ in range(args.rounds)) / 1e3
        phase_ms = []
        for _ in range(3):
            start = time.perf_counter()
            phase.run()
            phase_ms.append((time.perf_counter() - start) * 1e3)
        result[f"threads_{threads}"] = {
            "infonce_step_ms": step_ms,
            f"contrastive_phase_{phase_steps}_steps_ms": statistics.median(phase_ms),
        }
    torch.set_num_threads(args.threads)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--triplets", type=int, default=256, help="B (a batch is 3B)")
    parser.add_argument("--unsafe", type=float, default=0.2, help="fraction of unsafe slots")
    parser.add_argument("--calls", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1, help="torch threads for the sampler")
    parser.add_argument("--infonce-threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--out", type=Path, default=archive_path("sampler"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    load_before = os.getloadavg()
    by_size = {}
    for size in args.sizes:
        by_size[str(size)] = bench_size(size, args)
        print(size, json.dumps({k: round(v, 1) for k, v in by_size[str(size)].items()}))
    infonce = bench_infonce(args)
    print(json.dumps(infonce))
    smallest, largest = str(min(args.sizes)), str(max(args.sizes))
    report = {
        "command": "python benchmarks/sampler.py "
        + " ".join(
            f"--{k.replace('_', '-')} {' '.join(map(str, v)) if isinstance(v, list) else v}"
            for k, v in vars(args).items()
        ),
        "units": "microseconds per call (median over rounds of per-round medians), "
        "except *_ms entries",
        "triplets_B": args.triplets,
        "unsafe_fraction": args.unsafe,
        "by_size": by_size,
        "contrastive_index_ratio_largest_vs_smallest": (
            by_size[largest]["contrastive_index"] / by_size[smallest]["contrastive_index"]
        ),
        "contrastive_batch_ratio_largest_vs_smallest": (
            by_size[largest]["contrastive_batch"] / by_size[smallest]["contrastive_batch"]
        ),
        "infonce": infonce,
        "machine": {
            "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "torch": torch.__version__,
            "python": platform.python_version(),
            "load_average_before": load_before,
            "load_average_after": os.getloadavg(),
        },
    }
    write_report(args.out, report)


if __name__ == "__main__":
    main()
