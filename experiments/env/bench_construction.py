"""What a `NavEnv` costs before its first step: construction, first reset, every goal's raster.

    OMP_NUM_THREADS=1 python experiments/env/bench_construction.py --scene data/scenes/demo \
        --episodes data/scenes/demo/episodes.json [--num 100] [--batch 8] [--cold]

Camera off (the cost measured here is the planners', not the renderer's). Loads the scene, navmesh and
episodes (not timed), then times in process CPU seconds (other jobs on the shared machine count less
than in wall time): building the env, its first reset, making every goal's raster ready (the old code
built them all at construction; the new one builds each on its first lookup), and a second env over
the same parts in the same process (a training run's collector env beside its BC env). `--cold` first
deletes this navmesh's on-disk raster cache (`navmesh_raster_*` beside navmesh.npz) so the first env
builds everything; without it a second run shows the disk cache. Runs on old code too (no cache there).
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from pathlib import Path

import torch


def cpu(fn):
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, required=True)
    ap.add_argument("--episodes", type=Path, required=True)
    ap.add_argument("--split", default=None)
    ap.add_argument("--num", type=int, default=None, help="first N episodes (default: all of the split)")
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--cold", action="store_true", help="delete this navmesh's on-disk raster cache first")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from planners import NavMesh
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene.loader import load_scene

    scene = load_scene(args.scene)
    navmesh = NavMesh.load(scene.navmesh_path)
    episodes = load_episodes(args.episodes, split=args.split)[:args.num]
    if args.cold:
        for d in Path(scene.navmesh_path).parent.glob(f"navmesh_raster_*_{getattr(navmesh, 'content_hash', '-')}"):
            shutil.rmtree(d)
    cfg = NavEnvConfig()
    cfg.camera.enabled = False
    cfg.goal_image = "none"  # goal views are pictures, not planners work
    make = lambda: make_nav_env(scene, episodes, navmesh, config=cfg, batch_size=args.batch, seed=0)  # noqa: E731
    env, t_build = cpu(make)
    _, t_reset = cpu(env.reset)
    raster = env.step_field
    _, t_all = cpu(lambda: raster.ensure() if hasattr(raster, "ensure") else None)
    env2, t_second = cpu(make)
    _, t_reset2 = cpu(env2.reset)
    print(f"{len(episodes)} episodes, {len(env.field)} goals, batch {args.batch}, 1 thread, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"CPU s: construction {t_build:.2f}, first reset {t_reset:.2f}, remaining goals' rasters {t_all:.2f}, "
          f"total {t_build + t_reset + t_all:.2f}; second env in this process: construction {t_second:.2f}, "
          f"first reset {t_reset2:.2f}")
    if hasattr(raster, "cache"):
        print(f"raster cache (first env): {raster.cache.stats}")


if __name__ == "__main__":
    main()
