"""What the training-time linear probe costs per epoch (``probe/accuracy``, ``probe/auc``).

    python research/studies/probe_cost.py [--calls 3] [--rounds 5] \
        [--out benchmarks/results/archive/<date>/probe_cost.json]

One thread, milliseconds per call of ``replay_probe`` (median over interleaved rounds): draw
1000 safe + 1000 unsafe transitions from a filled replay buffer (HalfCheetah-sized observations,
5% unsafe), embed them with the paper's policy encoder (17 -> 128 -> 128) and fit the logistic
regression on 70%, score on 30%. Buffer sizes 10k, 100k (the paper's) and 1M.

Results: ``docs/results.md`` (training-time probe).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from tensordict import TensorDict
from torchrl.data import Bounded, LazyTensorStorage, TensorDictReplayBuffer

from s3rl_torchrl.data import SafeUnsafeSampler
from s3rl_torchrl.diagnostics.probe import replay_probe
from s3rl_torchrl.modules import build_s3rl_actor, get_policy_encoder

OBS_DIM, ACTION_DIM = 17, 6


def filled_buffer(size: int) -> TensorDictReplayBuffer:
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(size, OBS_DIM, generator=g)
    safe = torch.rand(size, 1, generator=g) >= 0.05
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(size), sampler=SafeUnsafeSampler())
    rb.extend(TensorDict({"observation": obs, "next": {"safe": safe}}, batch_size=[size]))
    return rb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=archive_path("probe_cost"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    spec = Bounded(-torch.ones(ACTION_DIM), torch.ones(ACTION_DIM), (ACTION_DIM,))
    encoder = get_policy_encoder(build_s3rl_actor(OBS_DIM, spec, hidden=(128, 128)))
    buffers = {size: filled_buffer(size) for size in (10_000, 100_000, 1_000_000)}
    cases = {
        f"buffer_{size}": (lambda rb=rb: replay_probe(rb, encoder, seed=1))
        for size, rb in buffers.items()
    }
    times = interleaved_rounds(cases, args.calls, args.rounds, warmup=1)
    ms = {name: statistics.median(t) / 1e3 for name, t in times.items()}
    for name, value in ms.items():
        print(f"{name:>16}: {value:7.1f} ms per epoch")
    write_report(args.out, {"ms_per_call_median": ms, "ms_per_call_rounds": {
        name: [t / 1e3 for t in ts] for name, ts in times.items()}})


if __name__ == "__main__":
    main()
