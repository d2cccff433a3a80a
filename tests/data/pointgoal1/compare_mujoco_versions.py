"""Why the native SafetyPointGoal1 parts from Safety-Gymnasium's recording: the MuJoCo version.

Runs Safety-Gymnasium's *own* world (the MJCF its builder generates for each recorded seed) under
the project's MuJoCo with the recorded actions, and compares it with the recording (mujoco 2.3.3)
and with the native env (``s3rl_torchrl/envs/goal.py``). Two steps, one per venv:

    # 1. oracle venv: write Safety-Gymnasium's worlds (not kept in the repository)
    /work/oracle-venv/bin/python tests/data/pointgoal1/compare_mujoco_versions.py dump /tmp/sg_worlds.json
    # 2. project venv: step them under the installed MuJoCo and compare
    .venv/bin/python tests/data/pointgoal1/compare_mujoco_versions.py compare /tmp/sg_worlds.json

The second step prints, per seed, the first step at which Safety-Gymnasium's world under the
installed MuJoCo leaves the recording (sensors by more than 1e-4 and 1e-3, agent position by more
than 1e-6 and 1e-3), and the largest difference between that world and the native env over the
whole recording (sensors and joint positions).
"""

from __future__ import annotations

import argparse
import copy
import json
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def dump(out: Path) -> None:
    warnings.filterwarnings("ignore")
    import gymnasium
    import safety_gymnasium  # noqa: F401
    import xmltodict

    seeds = [int(s) for s in np.load(HERE / "oracle.npz")["seeds"]]
    worlds = {}
    for seed in seeds:
        env = gymnasium.make("SafetyPointGoal1Gymnasium-v0")
        env.reset(seed=seed)
        task = env.unwrapped.task
        xml = copy.deepcopy(task.world.xml)
        # Drop what needs Safety-Gymnasium's asset files (textures, materials): rendering only.
        xml["mujoco"].pop("asset")
        xml["mujoco"]["compiler"] = {"@angle": "radian"}
        for geom in xml["mujoco"]["worldbody"]["geom"]:
            geom.pop("@material", None)
        # The goal is moved after the XML is built (bases/base_task.py: build_goal_position).
        worlds[seed] = {"xml": xmltodict.unparse(xml),
                        "goal_pos": task.model.body("goal").pos.tolist()}
    out.write_text(json.dumps(worlds))
    print(f"wrote {out}")


def first(mask: np.ndarray) -> int | None:
    hits = np.flatnonzero(mask)
    return int(hits[0]) if len(hits) else None


def compare(path: Path) -> None:
    import gymnasium as gym
    import mujoco

    import s3rl_torchrl  # noqa: F401  (registers the tasks)

    recording = np.load(HERE / "oracle.npz")
    worlds = json.loads(path.read_text())
    print(f"mujoco {mujoco.__version__}; steps are 0-based indices into the recorded actions")
    for seed, world in worlds.items():
        key = f"s{seed}_"
        model = mujoco.MjModel.from_xml_string(world["xml"])
        data = mujoco.MjData(model)
        model.body("goal").pos[:] = world["goal_pos"]
        mujoco.mj_forward(model, data)
        native = gym.make("SafetyPointGoal1-v0").unwrapped
        native.reset(seed=int(seed))
        agent = model.body("agent").id
        sensors_vs_2_3_3, pos_vs_2_3_3, sensors_vs_native, qpos_vs_native = [], [], [], []
        for t, action in enumerate(recording[key + "action"]):
            data.ctrl[:] = np.clip(action, -1, 1)
            mujoco.mj_step(model, data, nstep=10)
            mujoco.mj_forward(model, data)
            native.step(action)
            sensors = data.sensordata[:12]
            sensors_vs_2_3_3.append(np.abs(sensors - recording[key + "obs"][t + 1][:12]).max())
            pos_vs_2_3_3.append(np.abs(data.xpos[agent, :2] - recording[key + "agent_xy"][t]).max())
            sensors_vs_native.append(np.abs(native.data.sensordata[:12] - sensors).max())
            qpos_vs_native.append(np.abs(native.data.qpos - data.qpos).max())
        s, p = np.array(sensors_vs_2_3_3), np.array(pos_vs_2_3_3)
        print(f"seed {seed}: Safety-Gymnasium's world under this MuJoCo vs the 2.3.3 recording: "
              f"sensors > 1e-4 from step {first(s > 1e-4)}, > 1e-3 from {first(s > 1e-3)}; "
              f"agent position > 1e-6 from {first(p > 1e-6)}, > 1e-3 from {first(p > 1e-3)}. "
              f"Native env vs that world over {len(s)} steps: sensors max "
              f"{max(sensors_vs_native):.1e}, qpos max {max(qpos_vs_native):.1e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["dump", "compare"])
    parser.add_argument("worlds", type=Path)
    args = parser.parse_args()
    dump(args.worlds) if args.mode == "dump" else compare(args.worlds)


if __name__ == "__main__":
    main()
