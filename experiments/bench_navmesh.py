"""Navmesh benchmark on the three shared Recast test levels (prints figures; not a test).

    python experiments/bench_navmesh.py [--cpu] [--threads 1] [--pairs 200] [--levels dungeon nav_test undulating]

Reports per level: bake time, walkable area / islands / triangles / corners, find_path median,
batched geodesic_distance throughput, distance-field build time, field lookup and
move_along_surface time for 64 agents, and the ratio to Recast's published figures
(bake 13-90 ms per level, path query 3-6 us).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

from planners import NavMesh, NavMeshSettings

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"
RECAST_BAKE_MS = (13.0, 90.0)
RECAST_PATH_US = (3.0, 6.0)


CLOCK = time.perf_counter  # --cpu switches to process CPU time (fairer on a machine shared with others)


def timed(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t = CLOCK()
        fn()
        out.append(CLOCK() - t)
    return out


def bench_level(path: Path, pairs: int, repeat_bake: int) -> dict:
    mesh = trimesh.load(path, force="mesh")
    bake_s = timed(lambda: NavMesh.bake(mesh, NavMeshSettings()), repeat_bake)
    nm = NavMesh.bake(mesh, NavMeshSettings())
    pts = nm.random_navigable_points(2 * pairs, seed=0)
    a, b = pts[:pairs], pts[pairs:]
    nm.find_path(a[0], b[0])  # warm-up
    path_s = [timed(lambda i=i: nm.find_path(a[i], b[i]), 1)[0] for i in range(pairs)]
    # process_time ticks coarsely on some systems: also time the whole loop
    loop_s = timed(lambda: [nm.find_path(a[i], b[i]) for i in range(pairs)], 1)[0] / pairs
    big = nm.random_navigable_points(4000, seed=1)
    nm.geodesic_distance(big[:100], big[100:200])
    geo_s = min(timed(lambda: nm.geodesic_distance(big[:2000], big[2000:]), 3))
    reach = float(torch.isfinite(nm.geodesic_distance(big[:2000], big[2000:])).float().mean())
    goal = nm.random_navigable_points(1, seed=2)
    field_s = statistics.median(timed(lambda: nm.distance_field(goal), 5))
    f = nm.distance_field(goal)
    agents = torch.tensor(nm.random_navigable_points(64, seed=3))
    gi = torch.zeros(64, dtype=torch.long)
    f.lookup(agents, gi)
    look_s = statistics.median(timed(lambda: f.lookup(agents, gi), 50))
    step = agents + torch.tensor([0.25, 0.0, 0.0], dtype=torch.float64)
    nm.move_along_surface(agents, step)
    move_s = statistics.median(timed(lambda: nm.move_along_surface(agents, step), 50))
    return {"nm": nm, "bake_s": bake_s, "path_med_s": statistics.median(path_s), "path_mean_s": loop_s, "geo_pairs_per_s": 2000 / geo_s,
            "reach": reach, "field_s": field_s, "lookup64_s": look_s, "move64_s": move_s}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--repeat-bake", type=int, default=3)
    ap.add_argument("--levels", nargs="+", default=["dungeon", "nav_test", "undulating"])
    ap.add_argument("--cpu", action="store_true", help="time with process CPU time instead of wall-clock")
    args = ap.parse_args()
    global CLOCK
    if args.cpu:
        CLOCK = time.process_time
    torch.set_num_threads(args.threads)
    clock = "process CPU time" if args.cpu else "wall-clock"
    print(f"torch threads: {torch.get_num_threads()}  (timings: {clock}; load average {os.getloadavg()[0]:.1f})")
    for name in args.levels:
        r = bench_level(DATA / f"{name}.obj", args.pairs, args.repeat_bake)
        nm = r["nm"]
        bake_med = statistics.median(r["bake_s"]) * 1e3
        path_us = r["path_med_s"] * 1e6
        print(f"\n== {name}: {nm}")
        print(f"  bake            median {bake_med:8.0f} ms  (min {min(r['bake_s']) * 1e3:.0f})   "
              f"x{bake_med / RECAST_BAKE_MS[1]:.0f}-x{bake_med / RECAST_BAKE_MS[0]:.0f} Recast's 13-90 ms")
        print(f"  find_path       median {path_us / 1e3:8.2f} ms (mean {r['path_mean_s'] * 1e3:.2f})  "
              f"x{path_us / RECAST_PATH_US[1]:.0f}-x{path_us / RECAST_PATH_US[0]:.0f} Recast's 3-6 us")
        print(f"  geodesic_distance      {r['geo_pairs_per_s']:8.0f} pairs/s (batch 2000, {100 * r['reach']:.0f}% reachable)")
        print(f"  distance_field build   {r['field_s'] * 1e3:8.2f} ms (1 goal)")
        print(f"  field lookup, 64 agents {r['lookup64_s'] * 1e3:7.3f} ms")
        print(f"  move_along_surface, 64 {r['move64_s'] * 1e3:8.3f} ms")


if __name__ == "__main__":
    main()
