"""Record Safety-Gymnasium 1.0.0's own SafetyPointGoal1 for the parity tests of
``s3rl_torchrl/envs/goal.py`` (``tests/envs/test_goal.py``).

Runs in the oracle venv only (safety-gymnasium 1.0.0, gymnasium 0.28.1, mujoco 2.3.3; see
README.md), never in the project's environment:

    /work/oracle-venv/bin/python tests/data/pointgoal1/record_oracle.py

Writes ``oracle.npz`` beside this file (``--out`` elsewhere). Per seed ``s`` (keys prefixed ``s<seed>_``):

- the layout after ``reset(seed=s)``, read from the oracle env's own state: agent position
  (body ``xpos``) and yaw (the ``agent_rot`` its world was built with, checked against the body's
  rotation matrix), goal, 8 hazard and 1 vase positions (body ``xpos``) and the vase's yaw;
  the model's agent ``body_quat`` and the initial ``qpos`` (to check how the pose is applied);
- an episode of ``STEPS`` steps of ``SafetyPointGoal1Gymnasium-v0`` driven by a controller that
  heads for the hazard nearest to the robot, then for the goal, then again (so the robot drives
  through hazards and reaches goals), with seeded noise on the actions: the actions, the
  observations (the reset's first), rewards, ``info["cost"]``, ``info["cost_hazards"]``, goal
  flags, the agent's position and yaw, the goal and vase positions after every step;
- ``POSES`` agent poses set directly (no dynamics: the agent body moved in the model, then
  ``mj_forward``), at and around every hazard and the goal and at random: the agent's world
  position and rotation matrix, the observation, the hazard cost and the goal distance;
- ``GOALS`` new goals: after ``WAIT`` steps at rest, the agent body is moved onto the goal and
  one step taken, which reaches it and draws the next goal from the layout generator; the new
  goals' positions (they depend on the generator's stream, not on the dynamics);

plus the model's physical constants (masses, inertias, friction, ...) under ``model_*``, and the
versions used under ``versions``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path

import gymnasium
import mujoco
import numpy as np

warnings.filterwarnings("ignore")
import safety_gymnasium  # noqa: E402  (registers the ids with gymnasium)

SEEDS = (0, 1, 2, 3)
STEPS = 250
POSES = 48
GOALS, WAIT = 3, 5
OUT = Path(__file__).resolve().parent / "oracle.npz"


def yaw_of(matrix: np.ndarray) -> float:
    return math.atan2(matrix[1, 0], matrix[0, 0])


def layout_of(task) -> dict:
    """The layout, from the oracle env's state (positions) and world config (yaws)."""
    data, config = task.data, task.world_info.world_config_dict
    agent_xy = data.body("agent").xpos[:2].copy()
    yaw = float(config["agent_rot"])
    # The yaw the world was built with is the body's rotation (to rounding).
    assert abs(math.remainder(yaw - yaw_of(data.body("agent").xmat.reshape(3, 3)), 2 * math.pi)) < 1e-12
    vase_yaw = float(config["free_geoms"]["vase0"]["rot"])
    assert abs(math.remainder(vase_yaw - yaw_of(data.body("vase0").xmat.reshape(3, 3)), 2 * math.pi)) < 1e-12
    return {
        "agent": np.r_[agent_xy, yaw],
        "goal": data.body("goal").xpos[:2].copy(),
        "hazards": np.array([data.body(f"hazard{i}").xpos[:2] for i in range(8)]),
        "vases": np.array([np.r_[data.body("vase0").xpos[:2], vase_yaw]]),
    }


def controller(task, target, rng) -> np.ndarray:
    """Turn towards ``target`` and push while roughly facing it, with noise."""
    pos, mat = task.agent.pos, task.agent.mat
    ego = (np.r_[target, 0.0] - pos) @ mat
    bearing = math.atan2(ego[1], ego[0])
    action = np.array([0.9 * math.cos(bearing), 2.0 * bearing]) + 0.2 * rng.standard_normal(2)
    return np.clip(action, -1.0, 1.0)


def record_episode(seed: int) -> dict:
    env = gymnasium.make("SafetyPointGoal1Gymnasium-v0")
    obs, _ = env.reset(seed=seed)
    task = env.unwrapped.task
    layout = layout_of(task)
    out = {f"layout_{k}": v for k, v in layout.items()}
    out["agent_body_quat"] = task.model.body("agent").quat.copy()
    out["qpos0"] = task.data.qpos.copy()
    rng = np.random.default_rng(1000 + seed)
    hazards = layout["hazards"]
    via_hazard = True
    rows = {k: [] for k in ("action", "obs", "reward", "cost", "cost_hazards", "goal_met",
                            "terminated", "truncated", "agent_xy", "agent_yaw", "goal_xy",
                            "vase_xy")}
    rows["obs"].append(obs)
    for _ in range(STEPS):
        agent_xy = task.agent.pos[:2]
        if via_hazard:
            nearest = hazards[np.argmin(np.linalg.norm(hazards - agent_xy, axis=1))]
            if np.linalg.norm(nearest - agent_xy) < 0.05:  # through its centre: now the goal
                via_hazard = False
            target = nearest
        else:
            target = task.goal.pos[:2]
        action = controller(task, target, rng)
        obs, reward, terminated, truncated, info = env.step(action)
        if info.get("goal_met", False):
            via_hazard = True  # next: the hazard nearest to the robot, then the new goal
        for key, value in (("action", action), ("obs", obs), ("reward", reward),
                           ("cost", info["cost"]), ("cost_hazards", info["cost_hazards"]),
                           ("goal_met", info.get("goal_met", False)),
                           ("terminated", terminated), ("truncated", truncated),
                           ("agent_xy", task.agent.pos[:2].copy()),
                           ("agent_yaw", yaw_of(task.agent.mat)),
                           ("goal_xy", task.goal.pos[:2].copy()),
                           ("vase_xy", task.data.body("vase0").xpos[:2].copy())):
            rows[key].append(value)
        if terminated or truncated:
            break
    out.update({k: np.asarray(v) for k, v in rows.items()})
    env.close()
    return out


def record_poses(seed: int) -> dict:
    """Agent poses set directly in the reset world: observation and cost without dynamics."""
    env = gymnasium.make("SafetyPointGoal1Gymnasium-v0")
    env.reset(seed=seed)
    builder = env.unwrapped
    task = builder.task
    layout = layout_of(task)
    rng = np.random.default_rng(2000 + seed)
    points = []
    for hazard in layout["hazards"]:  # centre, inside, near the edge on both sides
        for radius in (0.0, 0.1, 0.19, 0.21):
            angle = rng.uniform(0, 2 * math.pi)
            points.append(hazard + radius * np.array([math.cos(angle), math.sin(angle)]))
    points.append(layout["goal"])  # on the goal
    while len(points) < POSES:
        points.append(rng.uniform(-1.5, 1.5, size=2))
    rows = {k: [] for k in ("pose", "agent_pos", "agent_mat", "obs", "cost", "cost_hazards",
                            "dist_goal")}
    for xy in points:
        yaw = rng.uniform(0, 2 * math.pi)
        move_agent(task, xy[0], xy[1], yaw)
        obs = task.obs()
        cost = builder._cost()  # calculate_cost + indicator, as in a step
        rows["pose"].append((xy[0], xy[1], yaw))
        rows["agent_pos"].append(task.agent.pos)
        rows["agent_mat"].append(task.agent.mat)
        rows["obs"].append(obs)
        rows["cost"].append(cost["cost_sum"])
        rows["cost_hazards"].append(cost["cost_hazards"])
        rows["dist_goal"].append(task.dist_goal())
    env.close()
    return {f"poses_{k}": np.asarray(v) for k, v in rows.items()}


def move_agent(task, x: float, y: float, yaw: float) -> None:
    """Put the agent's body frame at ``(x, y, yaw)`` at rest, as the world builder does."""
    body = task.model.body("agent")
    body.pos[:] = (x, y, body.pos[2])
    body.quat[:] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    task.data.qpos[:3] = 0.0  # the agent's joints (slide x, slide y, hinge z)
    task.data.qvel[:] = 0.0
    mujoco.mj_forward(task.model, task.data)


def record_goals(seed: int) -> dict:
    """New goals drawn after the agent is moved onto the current one (no dynamics involved)."""
    env = gymnasium.make("SafetyPointGoal1Gymnasium-v0")
    env.reset(seed=seed)
    task = env.unwrapped.task
    for _ in range(WAIT):
        env.step(np.zeros(2))
    goals, yaws = [], []
    for _ in range(GOALS):
        yaw = yaw_of(task.agent.mat)
        move_agent(task, *task.goal.pos[:2], yaw)
        _, reward, terminated, _, info = env.step(np.zeros(2))
        assert info.get("goal_met") and not terminated and reward > 0.5
        goals.append(task.goal.pos[:2].copy())
        yaws.append(yaw)
    env.close()
    return {"new_goals": np.array(goals), "new_goals_yaw": np.array(yaws)}


def model_constants() -> dict:
    env = gymnasium.make("SafetyPointGoal1Gymnasium-v0")
    env.reset(seed=0)
    m = env.unwrapped.task.model
    bodies = ["agent", "vase0"]
    geoms = ["floor", "agent", "pointarrow", "vase0", "goal", "hazard0"]
    out = {
        "model_body_names": np.array(bodies),
        "model_body_mass": np.array([m.body(b).mass[0] for b in bodies]),
        "model_body_inertia": np.array([m.body(b).inertia for b in bodies]),
        "model_body_ipos": np.array([m.body(b).ipos for b in bodies]),
        "model_geom_names": np.array(geoms),
        "model_geom_size": np.array([m.geom(g).size for g in geoms]),
        "model_geom_friction": np.array([m.geom(g).friction for g in geoms]),
        "model_geom_condim": np.array([m.geom(g).condim[0] for g in geoms]),
        "model_geom_contype": np.array([m.geom(g).contype[0] for g in geoms]),
        "model_geom_conaffinity": np.array([m.geom(g).conaffinity[0] for g in geoms]),
        "model_dof_damping": m.dof_damping.copy(),
        "model_opt": np.array([m.opt.timestep, m.opt.impratio, m.opt.tolerance, m.opt.iterations,
                               m.opt.integrator, m.opt.cone, m.opt.solver]),
        "model_actuator_gear": m.actuator_gear[:, 0].copy(),
        "model_actuator_forcerange": m.actuator_forcerange.copy(),
        "model_actuator_ctrlrange": m.actuator_ctrlrange.copy(),
    }
    env.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    out = parser.parse_args().out
    data = model_constants()
    for seed in SEEDS:
        recorded = {**record_episode(seed), **record_poses(seed), **record_goals(seed)}
        for key, value in recorded.items():
            data[f"s{seed}_{key}"] = value
    data["seeds"] = np.array(SEEDS)
    data["versions"] = np.array(json.dumps({
        "safety_gymnasium": safety_gymnasium.__version__, "gymnasium": gymnasium.__version__,
        "mujoco": mujoco.__version__, "numpy": np.__version__, "python": sys.version.split()[0],
    }))
    np.savez_compressed(out, **data)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB)")
    for seed in SEEDS:
        print(f"seed {seed}: {len(data[f's{seed}_reward'])} steps, return "
              f"{data[f's{seed}_reward'].sum():.3f}, cost {data[f's{seed}_cost'].sum():.0f}, "
              f"goals {int(data[f's{seed}_goal_met'].sum())}; pose costs "
              f"{int(data[f's{seed}_poses_cost'].sum())}/{POSES}")


if __name__ == "__main__":
    main()
