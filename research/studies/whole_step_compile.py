"""The SAC-Lag gradient step as the recipe runs it (compiled loss forward; eager backward,
three fused Adam steps and the target update) against the whole step in one ``torch.compile``
region with compiled autograd (issue 28's "the whole update as one compiled region").

    python research/studies/whole_step_compile.py [--calls 100] [--rounds 9] \
        [--out benchmarks/results/archive/<date>/whole_step_compile.json]

``experiment=paper``, SAC-Lag, SafetyHalfCheetahVelocity-v1, one thread, a batch of 256
transitions of a short rollout. The whole-step case needs Adam with ``foreach`` (the recipe's
``fused=True`` Adam is marked ``torch.compiler.disable``, a graph break per optimizer) and
``torch._dynamo.config.compiled_autograd`` so that the backward is traced too.
``torch._dynamo.explain`` reports the graph breaks left; both cases are timed in interleaved
rounds in one process, with this process's CPU time.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from multiseed_throughput import env_rows, paper_agents, paper_config

from s3rl_torchrl.algorithms import SACLagStep
from s3rl_torchrl.trainer import compile_loss


def foreach_adams(optimizers):
    """The same parameter groups and settings in ``foreach`` Adams (compilable)."""
    return {
        name: torch.optim.Adam(
            [{k: v for k, v in g.items() if k not in ("fused", "foreach")} for g in o.param_groups],
            fused=False,
            foreach=True,
        )
        for name, o in optimizers.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--out", type=Path, default=archive_path("whole_step_compile"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = paper_config("SafetyHalfCheetahVelocity-v1", 2000, True, 1, None, 2000)
    ((recipe_agent, env),) = paper_agents(cfg, 1, compile_first=compile_loss)
    ((whole_agent, _),) = paper_agents(cfg, 1)
    batch = env_rows(cfg, env, cfg.algo.batch_size)
    loss, target_updater = whole_agent.loss, whole_agent.update.target_updater
    optimizers = foreach_adams(whole_agent.optimizers)

    # The recipe's own gradient step (loss, backward, optimizers, target update), uncompiled
    # inside, so that one torch.compile below takes all of it.
    whole_step = SACLagStep(loss, optimizers, target_updater, cfg.algo.update_order)

    torch._dynamo.config.compiled_autograd = True
    explained = torch._dynamo.explain(whole_step)(batch.copy())
    breaks = sorted({" ".join(b.reason.split())[:240] for b in explained.break_reasons})
    print({"graphs": explained.graph_count, "graph_breaks": explained.graph_break_count})
    for reason in breaks:
        print(" -", reason)
    torch._dynamo.reset()
    compiled_whole_step = compile_loss(whole_step)
    cases = {
        "recipe: compiled loss forward, eager backward + fused Adams + target update":
            lambda: recipe_agent.update(batch.copy()),
        "whole step in one torch.compile, compiled autograd, foreach Adams":
            lambda: compiled_whole_step(batch.copy()),
    }
    times = interleaved_rounds(cases, calls=args.calls, rounds=args.rounds, warmup=30,
                               clock=time.process_time)
    rows = []
    for name, values in times.items():
        row = {"case": name, "median_ms_per_step": round(statistics.median(values) / 1e3, 2),
               "min_ms_per_step": round(min(values) / 1e3, 2),
               "max_ms_per_step": round(max(values) / 1e3, 2)}
        print(row, flush=True)
        rows.append(row)
    write_report(args.out, {"rows": rows, "graphs": explained.graph_count,
                            "graph_breaks": explained.graph_break_count,
                            "graph_break_reasons": breaks})


if __name__ == "__main__":
    main()
