"""Did headless video make evaluation without video slower? The trainer's deterministic
evaluation, measured with one version of the code and then another, interleaved.

    python research/studies/eval_speed.py --trees <before tree> <after tree> \
        [--rounds 3] [--episodes 2] [--out research/results/<name>.json]

For each task of :data:`TASKS` (one per family) and each tree, a fresh process (the tree on
``PYTHONPATH``) imports the package, builds the trainer's test env (``make_env`` with
``eval.num_envs=2`` copies, seed 100 000, as ``trainer/builders.py``) and runs
``trainer.evaluation.evaluate`` for ``--episodes`` episodes with a fixed seeded 256 x 256 MLP as
the deterministic policy (no video), each rollout the task's episode length (the trainer's
``eval.max_steps: null``). It reports the wall and process CPU time of ``import s3rl_torchrl``
and the process CPU time per env step (every step of both copies). Trees and tasks are
interleaved round by round, so that load from other jobs hits both alike; the table gives the
median over rounds and a Mann-Whitney U test of after against before (``--summarise JSON``
recomputes it from a result file's rounds). Only APIs that both versions share are used (``make_env``, ``evaluate``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

TASKS = {
    "velocity": "SafetyHalfCheetahVelocity-v1",
    "circle": "SafetyPointCircle1-v0",
    "goal": "SafetyPointGoal1-v0",
    "bullet": "SafetyBallRun-v0",
}

CHILD = r"""
import json, sys, time
wall, cpu = time.perf_counter(), time.process_time()
import s3rl_torchrl
import_wall, import_cpu = time.perf_counter() - wall, time.process_time() - cpu
import torch
from tensordict.nn import TensorDictModule
from torchrl.modules import MLP
from s3rl_torchrl.envs import get_task, make_env
from s3rl_torchrl.trainer.evaluation import evaluate

torch.set_num_threads(1)
torch.manual_seed(0)
task, episodes = sys.argv[1], int(sys.argv[2])
env = make_env(task, num_envs=2, seed=100_000)
obs, act = env.observation_spec["observation"].shape[-1], env.action_spec.shape[-1]
net = torch.nn.Sequential(MLP(obs, act, num_cells=[256, 256]), torch.nn.Tanh())
module = TensorDictModule(net, in_keys=["observation"], out_keys=["action"])
steps = 0

def policy(tensordict):
    global steps
    steps += tensordict.batch_size.numel()
    return module(tensordict)

max_steps = get_task(task).max_episode_steps  # the trainer's eval.max_steps: null
evaluate(env, policy, 1, max_steps)  # warm-up: first-call allocations and lazy imports
steps, start = 0, time.process_time()
evaluate(env, policy, episodes, max_steps)
seconds = time.process_time() - start
print("ROW " + json.dumps({
    "import_wall_s": import_wall, "import_cpu_s": import_cpu,
    "eval_cpu_ms_per_step": 1000 * seconds / steps, "steps": steps,
    "mujoco_gl": __import__("os").environ.get("MUJOCO_GL"),
}))
"""


def measure(tree: str, task: str, episodes: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env["PYTHONPATH"] = tree
    done = subprocess.run(
        [sys.executable, "-c", CHILD, task, str(episodes)],
        capture_output=True, text=True, env=env, cwd=tree, check=True,
    )
    line = next(x for x in done.stdout.splitlines() if x.startswith("ROW "))
    return json.loads(line[4:])


def commit(tree: str) -> str | None:
    done = subprocess.run(["git", "-C", tree, "rev-parse", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() or None


def summarise(rows: dict[str, list[dict]]) -> list[dict]:
    """Per family: the medians over rounds, and a two-sided Mann-Whitney U test of after
    against before (the rounds of one version are not paired with the other's)."""
    from scipy.stats import mannwhitneyu

    summary = []
    for family, task in TASKS.items():
        before, after = rows[f"{family}/before"], rows[f"{family}/after"]
        row = {"family": family, "task": task}
        for key in ("eval_cpu_ms_per_step", "import_cpu_s"):
            b, a = [r[key] for r in before], [r[key] for r in after]
            row[f"{key}_before"], row[f"{key}_after"] = statistics.median(b), statistics.median(a)
            row[f"{key}_p"] = float(mannwhitneyu(a, b).pvalue)
        summary.append(row)
    # The import does not depend on the task: every process's, pooled.
    b = [r["import_cpu_s"] for k, v in rows.items() if k.endswith("/before") for r in v]
    a = [r["import_cpu_s"] for k, v in rows.items() if k.endswith("/after") for r in v]
    summary.append({"family": "all", "import_cpu_s_before": statistics.median(b),
                    "import_cpu_s_after": statistics.median(a),
                    "import_cpu_s_p": float(mannwhitneyu(a, b).pvalue)})
    return summary


def print_table(summary: list[dict]) -> None:
    print("| family | task | eval CPU ms/step before | after | p | import CPU s before | after | p |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for r in summary:
        step = (f"{r['eval_cpu_ms_per_step_before']:.2f} | {r['eval_cpu_ms_per_step_after']:.2f} "
                f"| {r['eval_cpu_ms_per_step_p']:.2f}") if "task" in r else "- | - | -"
        print(f"| {r['family']} | {r.get('task', '')} | {step} | {r['import_cpu_s_before']:.2f} "
              f"| {r['import_cpu_s_after']:.2f} | {r['import_cpu_s_p']:.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs=2, metavar=("BEFORE", "AFTER"))
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--summarise", type=Path, metavar="JSON",
                        help="recompute the summary of a result file's rounds, measure nothing")
    args = parser.parse_args()

    if args.summarise:
        result = json.loads(args.summarise.read_text())
        result["summary"] = summarise(result["rows"])
        args.summarise.write_text(json.dumps(result, indent=1) + "\n")
        print_table(result["summary"])
        return
    if not args.trees:
        parser.error("--trees BEFORE AFTER is required unless --summarise is given")
    rows: dict[str, list[dict]] = {}
    for _ in range(args.rounds):
        for family, task in TASKS.items():
            for label, tree in zip(("before", "after"), args.trees):
                rows.setdefault(f"{family}/{label}", []).append(
                    measure(tree, task, args.episodes))
    summary = summarise(rows)
    print_table(summary)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "trees": args.trees, "commits": [commit(tree) for tree in args.trees],
            "rounds": args.rounds, "episodes": args.episodes,
            "summary": summary, "rows": rows,
        }, indent=1) + "\n")


if __name__ == "__main__":
    main()
