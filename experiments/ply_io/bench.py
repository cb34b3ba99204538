"""Time reading and writing the real 3DGS PLYs (Gaussians.load / save) and a point-cloud PLY.

Run from a checkout root: `OMP_NUM_THREADS=1 PYTHONPATH=$PWD python experiments/ply_io/bench.py`;
run it with PYTHONPATH at an older checkout for the before figures. Prints the median of `--repeat`
runs per operation, milliseconds, plus the machine's load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.render import Gaussians
from wanderland_nav.scene.pointcloud import read_ply_points, write_ply_points

DATA = Path(os.environ.get("WANDERLAND_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))


def median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    torch.set_num_threads(1)
    tmp = Path(tempfile.mkdtemp())
    rows = []
    for name in ("guitar", "playbot"):
        path = DATA / "splats" / f"{name}.ply"
        g = Gaussians.load(path)
        rows.append((f"Gaussians.load {name} ({len(g)})", median_ms(lambda: Gaussians.load(path), args.repeat)))
        rows.append((f"Gaussians.save {name}", median_ms(lambda: g.save(tmp / f"{name}.ply"), args.repeat)))
    rng = np.random.default_rng(0)
    xyz, rgb = rng.normal(size=(500_000, 3)).astype(np.float32), rng.integers(0, 256, (500_000, 3)).astype(np.uint8)
    write_ply_points(tmp / "pc.ply", xyz, rgb)
    rows.append(("write_ply_points 500k", median_ms(lambda: write_ply_points(tmp / "pc.ply", xyz, rgb), args.repeat)))
    rows.append(("read_ply_points 500k", median_ms(lambda: read_ply_points(tmp / "pc.ply"), args.repeat)))
    for label, ms in rows:
        print(f"{label:34s} {ms:8.1f} ms")
    print("load average:", " ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
