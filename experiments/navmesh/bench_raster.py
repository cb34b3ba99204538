"""GeodesicRaster (O(1) env lookup) vs the exact GeodesicField: error, speed, build time, memory.

    python experiments/navmesh/bench_raster.py [--demo data/scenes/bench/tiny/navmesh.npz] [--points 4000]

On the demo navmesh (if given) and the three Recast levels in ../shared/data/meshes (baked with
Recast's defaults), for 8 random goals and `--points` random navigable points: the raster's error
against the exact field (e = raster - exact; the bound is 0 <= e <= 2 sqrt(2) cell_size), the share
of points above the bound, the exact fallbacks, us per point for both, build seconds and kB per goal.
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


def compare(nm: NavMesh, n_points: int, seed: int = 0) -> dict:
    goals = nm.random_navigable_points(8, seed=seed)
    field = nm.distance_field(goals)
    raster = field.raster()
    pts = nm.random_navigable_points(n_points, seed=seed + 1)
    gi = np.arange(n_points) % 8
    t0 = time.perf_counter()
    exact = field.lookup(pts, gi).numpy()
    t1 = time.perf_counter()
    fast = raster.lookup(pts, gi).numpy()
    t2 = time.perf_counter()
    fin = np.isfinite(exact)
    if not np.array_equal(fin, np.isfinite(fast)):
        raise AssertionError("raster and exact field disagree on reachability")
    e = fast[fin].astype(np.float64) - exact[fin]
    bound = 2 * np.sqrt(2) * nm.cs
    return {"cs": nm.cs, "pairs": raster.source.shape[1], "e_min": e.min(), "e_max": e.max(),
            "e_p99": np.quantile(e, 0.99), "over%": 100 * (e > bound + 1e-3).mean(), "exact_ok%": 100 * (np.abs(e) < 1e-3).mean(),
            "fallback%": 100 * raster.stats["exact_fallbacks"] / n_points, "us_exact": 1e6 * (t1 - t0) / n_points,
            "us_raster": 1e6 * (t2 - t1) / n_points, "build_s/goal": raster.build_seconds / 8,
            "kB/goal": raster.source.nbytes / 8 / 1e3, "index_kB": raster._pair_id.nbytes / 1e3}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", type=Path, default=None)
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"{args.points} points, 8 goals, {args.threads} threads, load average {os.getloadavg()[0]:.2f}")
    for name, nm in levels(args.demo):
        r = compare(nm, args.points)
        print(f"{name:>10}: " + "  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()),
              flush=True)


if __name__ == "__main__":
    main()
