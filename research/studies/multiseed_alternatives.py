"""Two ways to run K seeds faster than ``MultiSeedTrainer`` does, measured before building them.

    python research/studies/multiseed_alternatives.py [--seeds 5] [--out benchmarks/results/archive/<date>/multiseed_alternatives.json]

* **Step in two threads**: the K seeds' gradient step as two ``StackedSACLag`` groups (the first
  half of the seeds and the rest), run at once in two Python threads with one torch thread
  each, against one group of K with two torch threads (what the trainer does). Two threads
  per matrix product use the two cores poorly at these sizes; two products at once might not.
* **Collection as one env**: the K seeds' 10 training envs as ONE torchrl env of 10 K copies,
  the K actors as one ``vmap`` call (each seed's normal draws passed in, as the update does),
  against K envs and K policy calls (what the trainer's K collectors do). Both are timed as
  bare loops (policy, ``step_and_maybe_reset``), with the trainer's env and actor builders at
  paper settings, on ``SafetyHalfCheetahVelocity-v1``.

Each case is timed in interleaved rounds (median of 7), compiled step, two torch threads
unless stated.
"""

from __future__ import annotations

import argparse
import copy
import statistics
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
from _report import archive_path, interleaved_rounds, write_report
from multiseed_throughput import env_rows, paper_agents, paper_config
from tensordict import TensorDict

from s3rl_torchrl.algorithms.stacked import StackedSACLag, _normal_noise, draw_noise
from s3rl_torchrl.envs.make import make_env
from s3rl_torchrl.trainer.loop import compile_loss

TASK = "SafetyHalfCheetahVelocity-v1"


def step_cases(cfg, agents, envs) -> dict:
    batch = env_rows(cfg, envs[0], cfg.algo.batch_size)
    action_dim = batch["action"].shape[-1]

    def group(indices):
        stacked = StackedSACLag(
            [copy.deepcopy(agents[i].loss) for i in indices],
            cfg.algo.actor_lr, cfg.algo.critic_lr, cfg.algo.alpha_lr, cfg.algo.tau,
            compile_fn=compile_loss,
        )
        batches = torch.stack([batch] * len(indices))
        noise = torch.stack([draw_noise(cfg.algo.batch_size, action_dim) for _ in indices])
        return lambda: stacked.update(batches, noise)

    seeds = range(len(agents))
    whole = group(seeds)
    half = len(agents) // 2 + len(agents) % 2
    first, second = group(seeds[:half]), group(seeds[half:])
    for update in (whole, first, second):  # compiled one after the other, not in two threads
        update()
    pool = ThreadPoolExecutor(2)

    def one_group_two_torch_threads():
        torch.set_num_threads(2)
        whole()

    def two_groups_two_python_threads():
        torch.set_num_threads(1)  # process-wide: each Python thread computes on its own core
        for future in [pool.submit(first), pool.submit(second)]:
            future.result()

    return {
        f"step: one group of {len(agents)}, 2 torch threads": one_group_two_torch_threads,
        f"step: groups of {half} and {len(agents) - half} in 2 Python threads, 1 torch thread "
        "each": two_groups_two_python_threads,
    }


def collection_cases(cfg, agents, envs) -> dict:
    seeds, copies = len(agents), cfg.collector.num_envs
    joint = make_env(TASK, num_envs=seeds * copies, seed=0)
    action_dim = joint.action_spec.shape[-1]
    actor = agents[0].policy
    params = torch.stack([TensorDict.from_module(a.policy) for a in agents]).detach()

    def one_seed(seed_params, observation, noise):
        with seed_params.to_module(actor), _normal_noise([noise]):
            return actor(observation)

    policy = torch.vmap(one_seed, (0, 0, 0), randomness="error")
    state = {"joint": joint.reset(), "separate": [env.reset() for env in envs]}

    @torch.no_grad()
    def one_env():
        carrier = state["joint"]
        noise = torch.stack([torch.empty(copies, action_dim).normal_() for _ in range(seeds)])
        actions = policy(params, carrier.reshape(seeds, copies), noise)["action"]
        carrier.set("action", actions.reshape(seeds * copies, action_dim))
        _, state["joint"] = joint.step_and_maybe_reset(carrier)

    @torch.no_grad()
    def separate_envs():
        for index, (agent, env) in enumerate(zip(agents, envs, strict=True)):
            carrier = agent.policy(state["separate"][index])
            _, state["separate"][index] = env.step_and_maybe_reset(carrier)

    return {
        f"collect {seeds} x {copies} frames: {seeds} envs, {seeds} policy calls": separate_envs,
        f"collect {seeds} x {copies} frames: one env of {seeds * copies}, one vmapped policy "
        "call": one_env,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--out", type=Path,
                        default=archive_path("multiseed_alternatives"))
    args = parser.parse_args()
    torch.set_num_threads(2)
    cfg = paper_config(TASK, 0, True, 2, None, 10_000)
    agents, envs = map(list, zip(*paper_agents(cfg, args.seeds), strict=True))
    rows = []
    for cases in (step_cases(cfg, agents, envs), collection_cases(cfg, agents, envs)):
        times = interleaved_rounds(cases, calls=20, rounds=7, warmup=5)
        for name in cases:
            rows.append({"case": name, "seeds": args.seeds,
                         "median_wall_ms": round(statistics.median(times[name]) / 1e3, 3),
                         "min_wall_ms": round(min(times[name]) / 1e3, 3)})
            print(rows[-1], flush=True)
        torch.set_num_threads(2)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
