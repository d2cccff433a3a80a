"""Did ``SACLagLoss``'s faster critic evaluations pay for several seeds in one step? The
``StackedSACLag`` step of K agents with ``critic_eval="batched_mlp"`` against ``"vmap"``.

    PYTHONPATH=<checkout of 8e0ee0c> python research/studies/critic_eval_stacked.py \
        [--agents 5] [--compiled] [--out research/results/critic_eval_stacked.json]

It measures the version of the code that still had ``critic_eval`` (up to commit 8e0ee0c;
issue 37 kept ``"vmap"`` alone, research/2026-11-21-benchmark-studies.md, "The critic evaluations removed in issue 37"). That version's
``StackedSACLag`` ran ``"vmap"`` only after its template loss gave each critic tensordict its
batch size back inside the ``vmap`` over agents (what the later version does); the script
patches that in (``_before_issue37.py``). HalfCheetah sizes (17/6), 128x128 networks, batch 256, one cost, lambda 0.3;
both variants in one process, interleaved rounds of 10 steps, process CPU time, one thread.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _before_issue37 import give_template_batch_sizes, stacked_module
from _report import interleaved_rounds, write_report
from tensordict import TensorDict
from torchrl.data import Bounded

from s3rl_torchrl.modules import build_cost_qvalue_network, build_qvalue_network, build_s3rl_actor
from s3rl_torchrl.objectives import SACLagLoss
from s3rl_torchrl.trainer import compile_loss

OBS, ACT, BATCH = 17, 6, 256


def make_loss(critic_eval: str, seed: int) -> SACLagLoss:
    torch.manual_seed(seed)
    spec = Bounded(-torch.ones(ACT), torch.ones(ACT))
    loss = SACLagLoss(
        build_s3rl_actor(OBS, spec),
        [build_qvalue_network(OBS, ACT) for _ in range(2)],
        [build_cost_qvalue_network(OBS, ACT) for _ in range(2)],
        num_costs=1,
        critic_eval=critic_eval,
        action_spec=spec,
    )
    loss.make_value_estimator(gamma=0.99)
    loss.lagrangian = 0.3
    return loss


def batches(agents: int) -> TensorDict:
    g = torch.Generator().manual_seed(0)

    def randn(*shape):
        return torch.randn(agents, BATCH, *shape, generator=g)

    done = torch.zeros(agents, BATCH, 1, dtype=torch.bool)
    return TensorDict(
        {
            "observation": randn(OBS),
            "action": randn(ACT).clamp(-1, 1),
            "steps_to_next_obs": torch.ones(agents, BATCH, 1, dtype=torch.int64),
            "next": {
                "observation": randn(OBS),
                "reward": randn(1),
                "cost": randn(1).abs(),
                "terminated": done,
                "done": done,
            },
        },
        [agents, BATCH],
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=5)
    parser.add_argument("--compiled", action="store_true")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(1)
    stacked = stacked_module()
    give_template_batch_sizes(stacked)
    cases, compile_seconds = {}, {}
    for critic_eval in ("batched_mlp", "vmap"):
        group = stacked.StackedSACLag(
            [make_loss(critic_eval, seed) for seed in range(args.agents)],
            5e-4,
            1e-3,
            3e-4,
            0.05,
            compile_fn=compile_loss if args.compiled else None,
        )
        data = batches(args.agents)
        noise = torch.stack(
            [stacked.draw_noise(BATCH, ACT) for _ in range(args.agents)]
        )

        def step(group=group, data=data, noise=noise):
            group.update(data.clone(False), noise)

        start = time.perf_counter()
        step()
        step()
        compile_seconds[critic_eval] = round(time.perf_counter() - start, 1)
        cases[critic_eval] = step
    times = interleaved_rounds(
        cases, calls=10, rounds=args.rounds, warmup=2, clock=time.process_time
    )
    rows = [
        {
            "critic_eval": name,
            "agents": args.agents,
            "compiled": args.compiled,
            "median_cpu_ms_per_step": round(statistics.median(values) / 1e3, 2),
            "min_cpu_ms": round(min(values) / 1e3, 2),
            "max_cpu_ms": round(max(values) / 1e3, 2),
            "first_two_steps_s": compile_seconds[name],
        }
        for name, values in times.items()
    ]
    for row in rows:
        print(row)
    if args.out is not None:
        write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
