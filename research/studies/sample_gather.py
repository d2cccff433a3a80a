"""What a gradient step's batch costs to draw: torchrl's ``replay_buffer.sample()`` against a
hand-written gather into a preallocated batch (the alternative issue 28 names).

    python research/studies/sample_gather.py [--threads 1] [--calls 200] [--rounds 9] \
        [--out benchmarks/results/archive/<date>/sample_gather.json]

The buffer is the recipe's (``build_replay_buffer`` at ``experiment=paper`` settings: 100 000
slots, ``SafeUnsafeSampler``, batch 256) filled with 100 000 transitions of the keys the
recipe stores for S3RL on HalfCheetah, random values. Cases, timed in interleaved rounds in one
process:

- ``sample(), LazyTensorStorage``: torchrl's buffer as it comes (index draw, TensorDict
  indexing of every key);
- ``sample(), GatherStorage``: the recipe's buffer (``s3rl_torchrl.data.GatherStorage``: one
  ``index_select`` per stored tensor), what the trainer calls;
- ``index draw + torch.index_select into a reused batch``: the sampler's index draw, then one
  ``index_select(out=...)`` per stored tensor into tensors allocated once: the least a gather
  can cost here while keeping the sampler;
- ``index draw only``: ``sampler.sample(storage, 256)``.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, recipe_config, write_report
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.trainer.builders import build_replay_buffer

SLOTS = 100_000


def filled_buffer(cfg, storage=None):
    buffer = build_replay_buffer(cfg.algo)
    if storage is not None:  # the same buffer on another storage class
        buffer = TensorDictReplayBuffer(storage=storage(SLOTS), sampler=buffer.sampler,
                                        batch_size=buffer.batch_size)
    obs, act = 17, 6
    data = TensorDict(
        {
            "observation": torch.randn(SLOTS, obs),
            "action": torch.rand(SLOTS, act) * 2 - 1,
            "steps_to_next_obs": torch.randint(1, 3, (SLOTS, 1)),
            "next": {
                "observation": torch.randn(SLOTS, obs),
                "reward": torch.randn(SLOTS, 1),
                "cost": (torch.rand(SLOTS, 1) < 0.1).float(),
                "done": torch.zeros(SLOTS, 1, dtype=torch.bool),
                "terminated": torch.zeros(SLOTS, 1, dtype=torch.bool),
                "safe": torch.rand(SLOTS, 1) > 0.1,
            },
        },
        [SLOTS],
    )
    buffer.extend(data)
    return buffer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--out", type=Path, default=archive_path("sample_gather"))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    cfg = recipe_config("experiment=paper", "algo=s3rl")
    buffer = filled_buffer(cfg)
    torchrl_buffer = filled_buffer(cfg, LazyTensorStorage)
    storage, sampler, batch_size = buffer._storage, buffer._sampler, cfg.algo.batch_size
    stored = storage._storage  # the TensorDict of [SLOTS] tensors torchrl keeps
    leaves = list(stored.items(True, True))
    out = TensorDict(
        {key: torch.empty(batch_size, *value.shape[1:], dtype=value.dtype)
         for key, value in leaves},
        [batch_size],
    )
    pairs = [(value, out.get(key)) for key, value in leaves]

    def gather():
        index, _ = sampler.sample(storage, batch_size)
        index = torch.as_tensor(index)
        for value, target in pairs:
            torch.index_select(value, 0, index, out=target)
        return out

    cases = {
        "sample(), LazyTensorStorage": torchrl_buffer.sample,
        "sample(), GatherStorage": buffer.sample,
        "index draw + torch.index_select into a reused batch": gather,
        "index draw only": lambda: sampler.sample(storage, batch_size),
    }
    times = interleaved_rounds(cases, calls=args.calls, rounds=args.rounds, warmup=20)
    rows = []
    for name, values in times.items():
        row = {"case": name, "median_us_per_batch": round(statistics.median(values), 1),
               "min_us_per_batch": round(min(values), 1), "threads": args.threads,
               "stored_tensors": len(leaves)}
        print(row, flush=True)
        rows.append(row)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
