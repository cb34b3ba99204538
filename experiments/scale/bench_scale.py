"""Scaling figures: collector frames/s vs workers, memory per scene, scene preparation time.

    OMP_NUM_THREADS=1 python experiments/scale/bench_scale.py --scenes /tmp/scale_demo_set --workers 1 2 4
    OMP_NUM_THREADS=1 python experiments/scale/bench_scale.py --scenes /tmp/scale_demo_set --workers 2 --ray

The scenes are a prepared demo set (`python -m wanderland_nav.make_episodes scene=demo_set scene.set.root=<dir>`).
Collection: the CityWalker-style demo policy (32 px, 10k LOD Gaussians) acting in a MultiSceneNavEnv
(B=4 agents per worker, 2 scenes active) through `make_collector` (1 worker: `Collector` in-process;
N > 1: `MultiSyncCollector` of N processes; `--ray`: `RayCollector` of N actors); frames/s is measured
over the iterations after the first (process start-up and scene loading excluded, reported apart).
Memory per scene: `measure_bytes` of one scene's NavEnv (navmesh, distance field, LOD Gaussians, episode
table, state), the figure the LRU budget counts.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import torch

from policies import make_policy
from wanderland_nav.compose.build import shaped_env_config
from wanderland_nav.compose.scene_sets import scene_env_fn
from wanderland_nav.envs.config import NavEnvConfig, TerminationConfig
from wanderland_nav.envs.multi_scene import measure_bytes
from wanderland_nav.rl.ppo import make_actor, make_collector
from wanderland_nav.rl.scene_sets import multi_scene_env_fn
from wanderland_nav.scene.sets import load_scene_set


def setup(scene_root: str):
    s = load_scene_set(scene_root)
    paths = {e.scene_id: str(e.path) for e in s}
    torch.manual_seed(0)
    policy = make_policy("citywalker", encoder="cnn", image_size=(32, 32), dim=128, depth=2, heads=4)
    cfg = shaped_env_config(NavEnvConfig(termination=TerminationConfig(max_steps=100)), policy)
    return paths, policy, cfg


def memory_per_scene(paths, cfg) -> None:
    for sid in paths:
        t0 = time.perf_counter()
        env = scene_env_fn(paths, cfg, split="train", lod_px=2.0)(sid, 4, 0)
        dt = time.perf_counter() - t0
        print(f"memory {sid}: {measure_bytes(env) / 2**20:.1f} MiB (NavEnv B=4, 10k LOD Gaussians), load {dt:.1f}s")


def collect_fps(paths, policy, cfg, workers: int, iters: int, use_ray: bool) -> None:
    fpb = 4 * workers * 8  # 8 steps of 4 agents per worker per batch
    env_fn = multi_scene_env_fn(list(paths), scene_env_fn(paths, cfg, split="train", lod_px=2.0),
                                batch_size=4, num_active=2, seed=0)
    t0 = time.perf_counter()
    c = make_collector(env_fn, make_actor(policy), frames_per_batch=fpb, total_frames=fpb * iters,
                       num_workers=workers, seed=0, ray={"address": None, "cpus_per_worker": 1} if use_ray else None)
    it, t_first, n = iter(c), None, 0
    next(it)
    t_first = time.perf_counter() - t0
    t1 = time.perf_counter()
    for batch in it:
        n += batch.numel()
    dt = time.perf_counter() - t1
    c.shutdown()
    kind = "ray" if use_ray else ("single" if workers == 1 else "multi")
    print(f"collect {kind} workers={workers}: {n / dt:.1f} frames/s ({n} frames in {dt:.1f}s after a first batch "
          f"of {t_first:.1f}s incl. start-up); load {os.getloadavg()[0]:.1f}")


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--scenes", required=True)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--iters", type=int, default=4)
    p.add_argument("--ray", action="store_true")
    p.add_argument("--no-memory", action="store_true")
    a = p.parse_args()
    torch.set_num_threads(1)
    print(f"load average {os.getloadavg()}, cores {os.cpu_count()}")
    paths, policy, cfg = setup(a.scenes)
    if not a.no_memory:
        memory_per_scene(paths, cfg)
    for w in a.workers:
        collect_fps(paths, policy, cfg, w, a.iters, a.ray)


if __name__ == "__main__":
    main()
