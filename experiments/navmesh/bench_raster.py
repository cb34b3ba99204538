"""GeodesicRaster (O(1) env lookup) vs the exact GeodesicField: error, speed, build time, memory.

    python experiments/navmesh/bench_raster.py [--demo data/scenes/bench/tiny/navmesh.npz] [--points 4000]

On the demo navmesh (if given) and the three Recast levels in ../shared/data/meshes (baked with
Recast's defaults), for 8 random goals and `--points` random navigable points: the raster's error
against the exact field (e = raster - exact; the bound is 0 <= e <= 2 sqrt(2) cell_size), the share
of points above the bound, the share answered exactly, the exact fallbacks; then the cost of one
env-sized query (`--batch` agents, 8 goals, best of 30, process CPU time so other jobs on the
machine count less) for both, and the raster's build CPU seconds and kB per goal.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

from planners import NavMesh, NavMeshSettings

SHARED = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "meshes"


def levels(demo: Path | None):
    import trimesh

    if demo is not None:
        yield "demo", NavMesh.load(demo)
    for name in ("dungeon", "nav_test", "undulating"):
        yield name, NavMesh.bake(trimesh.load(SHARED / f"{name}.obj", force="mesh"), NavMeshSettings())


def cpu_us_per_query(fn, pts, gi, repeats: int = 30) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        fn(pts, gi)
        best = min(best, time.process_time() - t0)
    return 1e6 * best


def compare(nm: NavMesh, n_points: int, batch: int, seed: int = 0) -> dict:
    goals = nm.random_navigable_points(8, seed=seed)
    field = nm.distance_field(goals)
    t0 = time.process_time()
    raster = field.raster()
    if hasattr(raster, "ensure"):  # built lazily since the batched build: time all 8 goals here
        raster.ensure()
    build_cpu = time.process_time() - t0
    pts = nm.random_navigable_points(n_points, seed=seed + 1)
    gi = np.arange(n_points) % 8
    exact = field.lookup(pts, gi).numpy()
    fast = raster.lookup(pts, gi).numpy()
    fallbacks = raster.stats["exact_fallbacks"]
    fin = np.isfinite(exact)
    if not np.array_equal(fin, np.isfinite(fast)):
        raise AssertionError("raster and exact field disagree on reachability")
    e = fast[fin].astype(np.float64) - exact[fin]
    bound = 2 * np.sqrt(2) * nm.cs
    return {"cs": nm.cs, "pairs": raster.source.shape[1], "e_min": e.min(), "e_max": e.max(),
            "e_p99": np.quantile(e, 0.99), "over%": 100 * (e > bound + 1e-3).mean(), "exact_ok%": 100 * (np.abs(e) < 1e-3).mean(),
            "fallback%": 100 * fallbacks / n_points,
            f"us_exact@{batch}": cpu_us_per_query(field.lookup, pts[:batch], gi[:batch]),
            f"us_raster@{batch}": cpu_us_per_query(raster.lookup, pts[:batch], gi[:batch]),
            "build_cpu_s/goal": build_cpu / 8,
            "kB/goal": raster.source.nbytes / 8 / 1e3, "index_kB": raster._pair_id.nbytes / 1e3}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", type=Path, default=None)
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--batch", type=int, default=256)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"{args.points} points, 8 goals, {args.threads} threads, load average {os.getloadavg()[0]:.2f}")
    for name, nm in levels(args.demo):
        r = compare(nm, args.points, args.batch)
        print(f"{name:>10}: " + "  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()),
              flush=True)


if __name__ == "__main__":
    main()
