"""Does the O(1) raster change what the env measures? The expert on the demo, raster vs exact field.

    python experiments/env/expert_raster_vs_exact.py [--scene data/scenes/bench/tiny] [--batch 16]

Runs the expert policy over every episode of the scene twice, once with the env's per-step distance
from `GeodesicRaster` (the default) and once from the exact `GeodesicField`, same seed, and prints
the largest per-episode difference of NE, SPL, success, steps and path length, relative to the
episode's shortest length where it is a distance.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import torch


def evaluate(scene, navmesh, batch: int, exact: bool):
    from wanderland_nav.envs import ExpertPolicy, NavEnvConfig
    from wanderland_nav.evaluation.loop import run_evaluation
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes

    cfg = NavEnvConfig()
    cfg.camera.enabled = False
    cfg.goal_image = "none"  # the expert reads no goal view (the episodes may name goal-image files)
    env = make_nav_env(scene, load_episodes(scene.episodes_path), navmesh, config=cfg, batch_size=batch, seed=0)
    if exact:
        env.step_field = env.field
    res = run_evaluation(env, ExpertPolicy(env), name="exact" if exact else "raster")
    return res, env


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=Path("data/scenes/bench/tiny"))
    ap.add_argument("--batch", type=int, default=16)
    args = ap.parse_args()
    torch.set_num_threads(2)
    from planners import NavMesh
    from wanderland_nav.scene import load_scene

    scene = load_scene(args.scene)
    navmesh = NavMesh.load(scene.navmesh_path)
    fast, env = evaluate(scene, navmesh, args.batch, exact=False)
    ref, _ = evaluate(scene, navmesh, args.batch, exact=True)
    print(f"{len(ref.records)} episodes, load average {os.getloadavg()[0]:.2f}, raster exact fallbacks "
          f"{env.step_field.stats['exact_fallbacks']} of {env.step_field.stats['queries']} lookups, steps with an "
          f"undefined distance {sum(r['undefined_distance_steps'] for r in fast.records)}")
    worst = {}
    for a, b in zip(fast.records, ref.records):
        assert a["episode_id"] == b["episode_id"]
        L = max(b["shortest_length"], 1e-9)
        for k, scale in (("navigation_error", L), ("path_length", L), ("spl", 1.0), ("steps", max(b["steps"], 1)),
                         ("success", 1.0)):
            diff = abs(float(a[k]) - float(b[k])) / scale
            if diff >= worst.get(k, (-1.0,))[0]:
                worst[k] = (diff, a["episode_id"], a[k], b[k])
    for k, (diff, eid, va, vb) in worst.items():
        print(f"  {k:>17}: largest relative difference {100 * diff:.3f} % (episode {eid}: raster {va}, exact {vb})")
    print("  raster:", {k: round(v, 4) for k, v in fast.summary["overall"].items()})
    print("  exact: ", {k: round(v, 4) for k, v in ref.summary["overall"].items()})


if __name__ == "__main__":
    main()
