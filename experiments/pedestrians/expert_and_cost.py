"""The expert among pedestrians (SR, collisions, yielding or not) and the crowd's cost to a camera-on env.

    python experiments/pedestrians/expert_and_cost.py --root <dir> [--episodes 24] [--batch 8] [--steps 10] [--res 64]
        [--part expert|cost|both]

The tiny demo block (seed 0) is built and prepared in `--root` when it is not there. Part 1: the expert
(camera off) on every episode with 0, 10 and 30 people per env instance, yielding (`ExpertPolicy`'s wait
rule) and not. Part 2: camera-on agent-frames/s of the expert-driven env with 0 and 30 people, side by side,
twice (the level-of-detail splat, `--res` pixels square, one history frame).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from planners import NavMesh
from wanderland_nav.envs import ExpertPolicy, NavEnvConfig
from wanderland_nav.evaluation.loop import run_evaluation
from wanderland_nav.envs.factory import make_nav_env
from wanderland_nav.envs.pedestrians.config import PedestrianConfig
from wanderland_nav.episodes import load_episodes
from wanderland_nav.episodes.generate import write_scene_episodes
from wanderland_nav.render.lod import load_splat
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.collision import CollisionSettings
from wanderland_nav.scene.demo import make_demo_scene
from wanderland_nav.preparation.scene import prepare_scene


def demo(root: Path, episodes: int):
    if not (root / "episodes.json").exists():
        make_demo_scene(root, seed=0, preset="tiny")
        prepare_scene(root, collision=CollisionSettings(voxel_size=0.25))
        sc = load_scene(root)
        write_scene_episodes(sc, NavMesh.load(sc.navmesh_path), root / "episodes.json", num_episodes=episodes, seed=0)
    scene = load_scene(root)
    return scene, NavMesh.load(scene.navmesh_path), load_episodes(scene.episodes_path)


def config(count: int, camera: bool, res: int = 8) -> NavEnvConfig:
    c = NavEnvConfig()
    c.camera.enabled = camera
    c.camera.width = c.camera.height = res
    c.camera.history = 1
    c.termination.max_steps = 300
    c.goal_image, c.observe_goal_image = "none", False
    c.pedestrians = PedestrianConfig(count=count)
    return c


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--episodes", type=int, default=24)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--part", choices=("expert", "cost", "both"), default="both")
    a = ap.parse_args()
    scene, nm, eps = demo(a.root, a.episodes)
    if a.part != "cost":
        expert_table(a, scene, nm, eps)
    if a.part != "expert":
        cost_table(a, scene, nm, eps)


def expert_table(a, scene, nm, eps) -> None:
    social = ("person_collisions", "intimate_seconds", "personal_seconds", "min_person_distance",
              "min_time_to_collision", "stalled_seconds", "jerk")
    print("| people | expert | N | SR | IR_pedestrian | " + " | ".join(social) + " |")
    print("|---|---|---|---|---|" + "---|" * len(social))
    for count in (0, 10, 30):
        for yielding in ((True, False) if count else (True,)):
            env = make_nav_env(scene, eps, nm, config=config(count, False), batch_size=a.batch)
            expert = ExpertPolicy(env)
            if not yielding:
                expert.crowd = None  # the same path follower, blind to people
            o = run_evaluation(env, expert, name="expert").summary["overall"]
            cells = " | ".join(f"{o[k]:.2f}" if k in o else "" for k in social)  # 0 people: not measured
            print(f"| {count} | {'yields' if yielding else 'does not yield'} | {o['episodes']} | {o['SR']:.3f} | "
                  f"{o['IR_pedestrian']:.3f} | {cells} |", flush=True)


def cost_table(a, scene, nm, eps) -> None:
    g = load_splat(scene.gaussians_path)
    print(f"\n| repeat | people | agent-frames/s | crowd and rules s | render s |  ({a.batch} agents, {a.res} px, "
          f"{a.steps} steps)")
    print("|---|---|---|---|---|")
    for rep in range(2):
        for count in (0, 30):
            env = make_nav_env(scene, eps, nm, config=config(count, True, a.res), batch_size=a.batch, gaussians=g)
            expert = ExpertPolicy(env)
            env.set_seed(0)
            td = env.reset()
            td = expert(td)
            _, td = env.step_and_maybe_reset(td)  # warm-up
            env.timings.clear()
            t0 = time.perf_counter()
            for _ in range(a.steps):
                td = expert(td)
                _, td = env.step_and_maybe_reset(td)
            wall = time.perf_counter() - t0
            tm = env.timings
            print(f"| {rep} | {count} | {a.batch * a.steps / wall:.1f} | {tm['rules']:.2f} | {tm['render']:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
