"""Milliseconds per full SAC / SAC-Lagrangian gradient step, eager and ``torch.compile``d.

    python benchmarks/loss_step.py [--steps 20] [--rounds 9] [--threads 1] \
        [--envs halfcheetah humanoid] [--modes eager compile] \
        [--out benchmarks/results/archive/<date>/loss_step.json]

Batch 256; actor ``build_s3rl_actor`` (128x128); critics ``build_qvalue_network`` (128x128): a
double reward critic and, for SAC-Lag, one double cost critic (one cost, lambda = 0.3). Adam
optimisers from ``make_sac_lag_optimizers`` (paper learning rates, fused Adam) for both losses,
``ForeachSoftUpdate(tau=0.05)`` (torchrl's ``SoftUpdate`` in one fused call). Two ways to take
one full step (critics, actor, alpha, targets):

- joint (torchrl's usual loop): ``loss(batch)``, one backward of the summed ``loss_*`` entries,
  the three optimiser steps, the soft update;
- ``*_fsrl``: FSRL's order, critic loss -> critic step -> actor loss (with the updated critics)
  -> actor step -> alpha step -> soft update (:func:`s3rl_torchrl.algorithms.sac_lag_update`).

Variants: ``sac`` / ``sac_fsrl`` (torchrl ``SACLoss``, loss_function="l2", alpha_init=0.005),
``sac_lag`` / ``sac_lag_fsrl`` (``SACLagLoss``). The ``critic_eval`` variants
(``sac_lag_fused_vmap``, ``sac_lag_vmap``) measured the loss's other critic evaluations, which
it no longer has (it evaluates its critics as ``SACLoss`` does, with ``vmap``); their results
stay in ``benchmarks/results/``.

All variants and modes of one env run in one fresh process, timed in interleaved rounds (each
round runs every configuration for ``--steps`` steps) so that load from other processes hits
all alike; the reported time is the median over rounds, as wall and as process CPU time (with
one thread the CPU time leaves out the time other processes hold the core). Each step takes a
fresh shallow copy of one batch that carries every entry of a real replay-buffer sample of the
recipe (``make_batch``). ``compile`` wraps the loss module (joint) or its two halves (fsrl) with
the trainer's ``compile_loss`` (``torch.compile``, default mode, isolated recompiles). Compile
time: each variant alone in a fresh process with inductor's on-disk caches off, wall time of the
first three steps minus three steady steps. Results: ``research/2026-11-21-benchmark-studies.md``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import platform
import statistics
import time
from pathlib import Path

import torch
from _report import archive_path, write_report
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.objectives import SACLoss

from s3rl_torchrl.algorithms import make_sac_lag_optimizers, sac_lag_update
from s3rl_torchrl.modules import build_cost_qvalue_network, build_qvalue_network, build_s3rl_actor
from s3rl_torchrl.objectives import ForeachSoftUpdate, SACLagLoss
from s3rl_torchrl.trainer import compile_loss

ENVS = {"halfcheetah": (17, 6), "humanoid": (376, 17)}
VARIANTS = ("sac", "sac_lag", "sac_fsrl", "sac_lag_fsrl")
COMPILE_VARIANTS = ("sac", "sac_lag", "sac_fsrl", "sac_lag_fsrl")
BATCH = 256
HIDDEN = (128, 128)


def make_batch(obs_dim: int, act_dim: int, batch: int = BATCH) -> TensorDict:
    """A batch with the entries of a replay-buffer sample of the S3RL recipe: what the losses
    read plus the safe/unsafe label and the buffer's slot index, which is all the trainer
    stores (``Trainer._keys_read_from_buffer``)."""
    g = torch.Generator().manual_seed(0)
    flag = torch.zeros(batch, 1, dtype=torch.bool)
    cost = (torch.rand(batch, 1, generator=g) > 0.7).float()
    return TensorDict(
        {
            "observation": torch.randn(batch, obs_dim, generator=g),
            "action": torch.rand(batch, act_dim, generator=g) * 2 - 1,
            "steps_to_next_obs": torch.full((batch,), 2, dtype=torch.long),
            "index": torch.arange(batch),  # stored by torchrl's TensorDict writer
            "next": {
                "observation": torch.randn(batch, obs_dim, generator=g),
                "reward": torch.randn(batch, 1, generator=g),
                "cost": cost,
                "done": flag,
                "terminated": flag,
                "safe": cost == 0,
            },
        },
        [batch],
    )


def make_loss(variant: str, obs_dim: int, act_dim: int):
    spec = Bounded(-torch.ones(act_dim), torch.ones(act_dim), (act_dim,))
    actor = build_s3rl_actor(obs_dim, spec, HIDDEN)
    critics = [build_qvalue_network(obs_dim, act_dim, HIDDEN) for _ in range(2)]
    if variant.startswith("sac_lag"):
        costs = [build_cost_qvalue_network(obs_dim, act_dim, HIDDEN) for _ in range(2)]
        loss = SACLagLoss(actor, critics, costs, num_costs=1)
        loss.lagrangian = 0.3
    else:
        loss = SACLoss(actor, critics, loss_function="l2", alpha_init=0.005)
    loss.make_value_estimator(gamma=0.99)
    return loss


class Stepper:
    """One full gradient step of one variant, eager or compiled."""

    def __init__(self, variant: str, obs_dim: int, act_dim: int, compiled: bool):
        torch.manual_seed(0)
        self.loss = loss = make_loss(variant, obs_dim, act_dim)
        self.optimizers = make_sac_lag_optimizers(loss)
        self.updater = ForeachSoftUpdate(loss, tau=0.05)
        self.batch = make_batch(obs_dim, act_dim)
        # The trainer's compile (isolated recompiles: the variants share torchrl's and
        # tensordict's forward wrappers, see compile_loss).
        wrap = compile_loss if compiled else (lambda f: f)
        if not variant.endswith("_fsrl"):
            self.forward = wrap(loss)
            self.step = self.joint_step
        else:
            self.critic_loss, self.actor_loss = wrap(loss.qvalue_v2_loss), wrap(loss.actor_loss)
            lag = isinstance(loss, SACLagLoss)
            self.step = self.sac_lag_fsrl_step if lag else self.sac_fsrl_step

    def fresh_batch(self) -> TensorDict:
        # A new batch object each step, as from a replay buffer: the losses write `td_error`
        # into their input, and a compiled loss fed the same object again would recompile.
        return self.batch.copy()

    def joint_step(self) -> None:
        out = self.forward(self.fresh_batch())
        total = sum(value for key, value in out.items() if key.startswith("loss_"))
        total.backward()
        for optimizer in self.optimizers.values():
            optimizer.step()
            optimizer.zero_grad(set_to_none=True)
        self.updater.step()

    def sac_lag_fsrl_step(self) -> None:
        sac_lag_update(
            self.loss,
            self.fresh_batch(),
            self.optimizers,
            self.updater,
            critic_loss=self.critic_loss,
            actor_loss=self.actor_loss,
        )

    def sac_fsrl_step(self) -> None:
        # The same order with torchrl's SACLoss pieces.
        opt = self.optimizers
        batch = self.fresh_batch()
        loss_qvalue, _ = self.critic_loss(batch)
        opt["critic"].zero_grad(set_to_none=True)
        loss_qvalue.backward()
        opt["critic"].step()
        loss_actor, metadata = self.actor_loss(batch)
        opt["actor"].zero_grad(set_to_none=True)
        loss_actor.backward()
        opt["actor"].step()
        loss_alpha = self.loss.alpha_loss(metadata["log_prob"]).mean()
        opt["alpha"].zero_grad(set_to_none=True)
        loss_alpha.backward()
        opt["alpha"].step()
        self.updater.step()


def timed(fn, n: int) -> tuple[float, float]:
    """(wall, process CPU) milliseconds per call. With one thread the CPU time excludes the time
    other processes hold the core, so it is the steadier number on a shared machine."""
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(n):
        fn()
    return (time.perf_counter() - wall) / n * 1e3, (time.process_time() - cpu) / n * 1e3


def bench(env: str, configs, steps: int, rounds: int) -> dict:
    """Time every ``(variant, mode)`` of ``configs`` in this process, interleaved."""
    obs_dim, act_dim = ENVS[env]
    steppers = {}
    for variant, mode in configs:
        stepper = Stepper(variant, obs_dim, act_dim, mode == "compile")
        for _ in range(8):  # the first calls compile (and recompile once: see docs)
            stepper.step()
        steppers[variant, mode] = stepper
    walls = {config: [] for config in steppers}
    cpus = {config: [] for config in steppers}
    for _ in range(rounds):
        for config, stepper in steppers.items():
            wall, cpu = timed(stepper.step, steps)
            walls[config].append(wall)
            cpus[config].append(cpu)
    result = {}
    for variant, mode in steppers:
        wall, cpu = statistics.median(walls[variant, mode]), statistics.median(cpus[variant, mode])
        result.setdefault(mode, {})[variant] = {
            "wall_ms": round(wall, 3),
            "cpu_ms": round(cpu, 3),
            "wall_ms_rounds": [round(x, 3) for x in walls[variant, mode]],
            "cpu_ms_rounds": [round(x, 3) for x in cpus[variant, mode]],
        }
    for mode, entries in result.items():
        for variant, entry in entries.items():
            # Each SAC-Lag variant against SACLoss taking its step the same way.
            base = "sac_fsrl" if variant.endswith("_fsrl") else "sac"
            if variant.startswith("sac_lag") and base in entries:
                for key in ("wall_ms", "cpu_ms"):
                    entry[f"{key[:-3]}_ratio_to_sac"] = round(entry[key] / entries[base][key], 3)
            if mode == "compile" and variant in result.get("eager", {}):
                eager = result["eager"][variant]
                entry["cpu_speedup_over_eager"] = round(eager["cpu_ms"] / entry["cpu_ms"], 3)
    return result


def compile_time(env: str, variant: str) -> float:
    """Cold compile time of one variant: run alone in a fresh process, on-disk caches off."""
    import torch._functorch.config as functorch_config
    import torch._inductor.config as inductor_config

    inductor_config.fx_graph_cache = False
    functorch_config.enable_autograd_cache = False
    stepper = Stepper(variant, *ENVS[env], compiled=True)
    start = time.perf_counter()
    for _ in range(3):
        stepper.step()
    first = time.perf_counter() - start
    for _ in range(3):
        stepper.step()
    steady = min(timed(stepper.step, 5)[0] for _ in range(3)) / 1e3
    return first - 3 * steady


def _worker(job: str, threads: int, *args):
    torch.set_num_threads(threads)
    return bench(*args) if job == "bench" else compile_time(*args)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20, help="steps per round and variant")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--envs", nargs="*", default=list(ENVS), choices=list(ENVS))
    parser.add_argument(
        "--modes", nargs="*", default=["eager", "compile"], choices=["eager", "compile"]
    )
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument(
        "--compile-variants",
        nargs="*",
        default=list(COMPILE_VARIANTS),
        choices=list(VARIANTS),
        help="variants timed in compile mode",
    )
    parser.add_argument("--out", type=Path, default=archive_path("loss_step"))
    args = parser.parse_args()

    load_before = os.getloadavg()
    results = {}
    # One fresh process per env; inside it every variant and mode is timed in the same
    # interleaved rounds (eager and compiled steps of one process compare reliably, across
    # processes the same step varied by up to ~20% here). Compile times come from one more
    # fresh process per compiled variant, so no earlier compilation hides them.
    ctx = mp.get_context("spawn")
    for env in args.envs:
        configs = []
        if "eager" in args.modes:
            configs += [(variant, "eager") for variant in args.variants]
        if "compile" in args.modes:
            configs += [(variant, "compile") for variant in args.compile_variants]
        with ctx.Pool(1) as pool:
            res = pool.apply(
                _worker, ("bench", args.threads, env, configs, args.steps, args.rounds)
            )
        for variant in res.get("compile", {}):
            with ctx.Pool(1) as pool:
                seconds = pool.apply(_worker, ("compile", args.threads, env, variant))
            res["compile"][variant]["compile_s"] = round(seconds, 1)
        results[env] = res
        for mode, entries in res.items():
            for variant, entry in entries.items():
                line = f"{env:12s} {mode:8s} {variant:19s} wall {entry['wall_ms']:7.2f} ms"
                line += f"  cpu {entry['cpu_ms']:7.2f} ms"
                if "cpu_ratio_to_sac" in entry:
                    line += f"  x{entry['cpu_ratio_to_sac']:.2f} of SAC (cpu)"
                if "cpu_speedup_over_eager" in entry:
                    line += f"  x{entry['cpu_speedup_over_eager']:.2f} faster than eager"
                if "compile_s" in entry:
                    line += f"  compile {entry['compile_s']} s"
                print(line, flush=True)
    payload = {
        "command": "python benchmarks/loss_step.py "
        + " ".join(
            f"--{k.replace('_', '-')} {' '.join(map(str, v)) if isinstance(v, list) else v}"
            for k, v in vars(args).items()
        ),
        "batch": BATCH,
        "hidden": list(HIDDEN),
        "threads": args.threads,
        "torch": torch.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "loadavg_before": [round(x, 2) for x in load_before],
        "loadavg_after": [round(x, 2) for x in os.getloadavg()],
        "results": results,
    }
    write_report(args.out, payload)


if __name__ == "__main__":
    main()
