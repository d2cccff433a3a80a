"""Why the package has its own ReLU: compiled ``torch.relu`` against ``s3rl_torchrl.modules.relu``.

    python research/studies/relu_mask.py [--calls 200] [--rounds 5] [--seeds 2] \
        [--out benchmarks/results/archive/<date>/relu_mask.json]

Two measurements, one thread, microseconds per call, median over interleaved rounds:

- ``mask``: storing the bool tensor ``x <= 0`` of one ``[4, 256, 128]`` activation (the shape of
  the four stacked critics' hidden layer), eager and compiled.
- ``critic_backward``: forward and input-gradient backward of a 3-layer ReLU ensemble of four
  critics (23 -> 128 -> 128 -> 1, batch 256, weights frozen as in the actor loss), eager
  and compiled, with ``torch.relu`` and with the package's ``relu``. With frozen weights the
  backward of ``torch.relu`` needs only the mask, which AOT autograd saves as bool.
- ``critic_backward vmap``: the same for ``--seeds`` agents under ``torch.vmap`` (what
  ``StackedSACLag`` compiles for several seeds in one process).

Results: ``research/2026-11-21-benchmark-studies.md`` ("The package's ReLU under torch.compile").
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report

from s3rl_torchrl.modules import relu

NETS, BATCH, IN, HIDDEN = 4, 256, 23, 128


def mask(x: torch.Tensor) -> torch.Tensor:
    return x <= 0


def make_critic_step(act, seeds: int | None = None):
    """``seeds``: that many agents' ensembles, stacked and run under ``torch.vmap``."""
    g = torch.Generator().manual_seed(0)
    lead = () if seeds is None else (seeds,)
    shapes = [(IN, HIDDEN), (HIDDEN, HIDDEN), (HIDDEN, 1)]
    weights = [torch.randn(*lead, NETS, a, b, generator=g) / a**0.5 for a, b in shapes]
    biases = [torch.zeros(*lead, NETS, 1, b) for _, b in shapes]
    action = torch.randn(*lead, NETS, BATCH, IN, generator=g, requires_grad=True)

    def one_agent(x, weights, biases):
        for i, (w, b) in enumerate(zip(weights, biases)):
            x = torch.baddbmm(b, x, w)
            if i < len(weights) - 1:
                x = act(x)
        return x.mean()

    if seeds is None:
        return lambda x: one_agent(x, weights, biases), action
    vmapped = torch.vmap(one_agent)
    return lambda x: vmapped(x, weights, biases).sum(), action


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=2, help="agents in the vmap case")
    parser.add_argument("--out", type=Path, default=archive_path("relu_mask"))
    args = parser.parse_args()
    torch.set_num_threads(1)

    x = torch.randn(NETS, BATCH, HIDDEN)
    compiled_mask = torch.compile(mask)
    cases = {"mask eager": lambda: mask(x), "mask compiled": lambda: compiled_mask(x)}
    vmap_case = f"critic_backward vmap K={args.seeds}"
    for seeds, case in ((None, "critic_backward"), (args.seeds, vmap_case)):
        for name, act in (("torch.relu", torch.relu), ("s3rl relu", relu)):
            for mode in ("eager", "compiled"):
                forward, action = make_critic_step(act, seeds)
                if mode == "compiled":
                    forward = torch.compile(forward)

                def step(forward=forward, action=action):
                    forward(action).backward()
                    action.grad = None

                cases[f"{case} {name} {mode}"] = step
    # The warm-up calls also compile.
    rounds = interleaved_rounds(cases, args.calls, args.rounds, warmup=5)
    rows = {
        name: {"us": round(statistics.median(values), 1), "rounds": [round(v, 1) for v in values]}
        for name, values in rounds.items()
    }
    for name, row in rows.items():
        print(f"{name:40s} {row['us']:9.1f} us")
    write_report(args.out, {"threads": 1, "seeds": args.seeds, "results": rows})


if __name__ == "__main__":
    main()
