"""The floor under the SAC-Lag gradient step on this machine: matmul throughput and a
plain-PyTorch copy of the step (no torchrl, no tensordict).

    python research/studies/plain_step.py [--threads 1 2] [--steps 200] [--rounds 5] \
        [--out benchmarks/results/archive/<date>/plain_step.json]

The plain step has the recipe's shapes and order (HalfCheetah: obs 17, act 6; batch 256;
128x128 ReLU networks; four Q-nets = double reward + double cost critic as one batched ensemble,
one ``baddbmm`` per layer; tanh-Gaussian actor; FSRL order: critic loss and step, actor loss
with the updated critics and step, alpha step, soft update with ``_foreach_lerp_``; fused Adam).
It is a yardstick for ``benchmarks/loss_step.py``, not a second implementation of the loss.
Each thread count runs in its own process; the median over rounds is reported.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import statistics
import time
from pathlib import Path

import _paths  # noqa: F401  (benchmarks/ on sys.path)
import torch
import torch.nn.functional as F
from _report import archive_path, write_report

OBS, ACT, HIDDEN, BATCH, NETS = 17, 6, 128, 256, 4


def matmul_gflops(n: int = 2000) -> float:
    a, b = torch.randn(BATCH, HIDDEN), torch.randn(HIDDEN, HIDDEN)
    for _ in range(100):
        a @ b
    start = time.perf_counter()
    for _ in range(n):
        a @ b
    return 2 * BATCH * HIDDEN * HIDDEN / ((time.perf_counter() - start) / n) / 1e9


def linear(fan_in: int, fan_out: int, nets: int | None = None) -> list[torch.Tensor]:
    shape = (nets, fan_out, fan_in) if nets else (fan_out, fan_in)
    bound = 1 / math.sqrt(fan_in)
    weight = torch.empty(shape).uniform_(-bound, bound).requires_grad_()
    bias = torch.zeros((nets, 1, fan_out) if nets else (fan_out,), requires_grad=True)
    return [weight, bias]


class PlainSACLag:
    def __init__(self) -> None:
        torch.manual_seed(0)
        self.actor = [*linear(OBS, HIDDEN), *linear(HIDDEN, HIDDEN), *linear(HIDDEN, 2 * ACT)]
        self.critics = [
            *linear(OBS + ACT, HIDDEN, NETS),
            *linear(HIDDEN, HIDDEN, NETS),
            *linear(HIDDEN, 1, NETS),
        ]
        self.targets = [p.detach().clone() for p in self.critics]
        self.log_alpha = torch.tensor(math.log(0.005), requires_grad=True)
        self.opt_actor = torch.optim.Adam(self.actor, 5e-4, fused=True)
        self.opt_critic = torch.optim.Adam(self.critics, 1e-3, fused=True)
        self.opt_alpha = torch.optim.Adam([self.log_alpha], 3e-4, fused=True)
        g = torch.Generator().manual_seed(1)
        self.obs, self.next_obs = torch.randn(BATCH, OBS, generator=g), torch.randn(BATCH, OBS)
        self.action = torch.rand(BATCH, ACT, generator=g) * 2 - 1
        self.signals = torch.stack([torch.randn(BATCH), (torch.rand(BATCH) > 0.7).float()])
        self.lagrangian = 0.3

    def policy(self, obs):
        w = self.actor
        h = torch.relu(F.linear(torch.relu(F.linear(obs, w[0], w[1])), w[2], w[3]))
        mean, log_std = F.linear(h, w[4], w[5]).chunk(2, -1)
        log_std = log_std.clamp(-20, 2)
        noise = torch.randn_like(mean)
        pre_tanh = mean + log_std.exp() * noise
        log_prob = (-0.5 * noise**2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        log_prob = log_prob - (2 * (math.log(2) - pre_tanh - F.softplus(-2 * pre_tanh))).sum(-1)
        return torch.tanh(pre_tanh), log_prob

    @staticmethod
    def q_values(x, p):  # [B, F] -> [NETS, B]
        h = torch.relu(torch.matmul(x, p[0].transpose(-1, -2)) + p[1])
        h = torch.relu(torch.baddbmm(p[3], h, p[2].transpose(-1, -2)))
        return torch.baddbmm(p[5], h, p[4].transpose(-1, -2)).squeeze(-1)

    def step(self) -> None:
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            next_action, next_log_prob = self.policy(self.next_obs)
            next_q = self.q_values(torch.cat([self.next_obs, next_action], -1), self.targets)
            next_value = next_q.view(2, 2, BATCH).min(1)[0] - alpha * next_log_prob
            target = self.signals + 0.99**2 * next_value
        q = self.q_values(torch.cat([self.obs, self.action], -1), self.critics).view(2, 2, BATCH)
        critic_loss = ((q - target.unsqueeze(1)) ** 2).mean(-1).sum()
        self.opt_critic.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.opt_critic.step()

        action, log_prob = self.policy(self.obs)
        frozen = [p.detach() for p in self.critics]
        q = self.q_values(torch.cat([self.obs, action], -1), frozen).view(2, 2, BATCH).min(1)[0]
        actor_loss = (alpha * log_prob - q[0] + self.lagrangian * q[1]).mean()
        actor_loss = actor_loss / (1 + self.lagrangian)
        self.opt_actor.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.opt_actor.step()

        alpha_loss = -(self.log_alpha * (log_prob.detach() - ACT)).mean()
        self.opt_alpha.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.opt_alpha.step()
        with torch.no_grad():
            torch._foreach_lerp_(self.targets, [p.detach() for p in self.critics], 0.05)


def measure(threads: int, steps: int, rounds: int) -> dict:
    torch.set_num_threads(threads)
    gflops = statistics.median(matmul_gflops() for _ in range(3))
    plain = PlainSACLag()
    for _ in range(50):
        plain.step()
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(steps):
            plain.step()
        times.append((time.perf_counter() - start) / steps * 1e3)
    return {
        "threads": threads,
        "matmul_256x128x128_gflops": round(gflops, 1),
        "plain_step_ms": round(statistics.median(times), 2),
        "plain_step_ms_rounds": [round(t, 2) for t in times],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, nargs="*", default=[1, 2])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=archive_path("plain_step"))
    args = parser.parse_args()
    rows = []
    ctx = mp.get_context("spawn")
    for threads in args.threads:
        with ctx.Pool(1) as pool:  # a fresh process per thread count
            row = pool.apply(measure, (threads, args.steps, args.rounds))
        print(json.dumps(row), flush=True)
        rows.append(row)
    write_report(args.out, {"rows": rows})


if __name__ == "__main__":
    main()
