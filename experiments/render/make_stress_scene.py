"""A scene at the paper's per-scene sizes, for benchmarks: >= 5,000 m2, >= 20M LiDAR points, 5M SH-3 Gaussians.

The Wanderland supplementary reports ~5M Gaussians per scene (SH degree 3) fitted to 10-50M LiDAR points
over 5,000-10,000 m2. This builds one from the default demo block (80 m x 40 m): the block twice, side by
side along the street (80 m x 80.4 m), each Gaussian split into children drawn inside it (smaller, same
colour and opacity, seeded SH-3 view dependence added) and each LiDAR point into jittered copies, until
the requested counts. The capture cameras, images and metadata are the demo's (they lie in the first
block), so `bench_lod.py --scene <out>` measures capture views and `prepare` / `make_episodes` run on it.

    python experiments/render/make_stress_scene.py --out data/scenes/stress_5m
        [--gaussians 5000000] [--points 20000000] [--seed 0]

Rerunning with the same arguments into a folder it wrote returns at once (a marker records them).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.render import Gaussians
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.demo import make_demo_scene
from wanderland_nav.scene.pointcloud import read_ply_points, write_ply_points

MARKER = ".stress_scene.json"
BLOCK_SHIFT = 40.4  # metres along the scene's z axis between the two copies of the demo block (40 m deep)


def upsample_gaussians(g: Gaussians, count: int, shift: np.ndarray, gen: torch.Generator) -> Gaussians:
    """`count` Gaussians from `g` and its copy shifted by `shift`: each parent split into children sampled
    inside it (0.6 of its spread), scales x0.6, same opacity and DC colour, SH degree 3 with small
    seeded higher coefficients (real captures carry view dependence there)."""
    both = torch.cat([g.means, g.means + torch.as_tensor(shift, dtype=g.means.dtype)])
    parent = torch.arange(count) % both.shape[0]
    src = parent % len(g)
    R = torch.nn.functional.normalize(g.quats[src], dim=-1)
    from wanderland_nav.render.projection import quat_scale_to_covar

    L = torch.linalg.cholesky(quat_scale_to_covar(R, g.scales[src]) + 1e-10 * torch.eye(3))
    eps = torch.randn(count, 3, 1, generator=gen) * 0.6
    means = both[parent] + (L @ eps)[..., 0]
    rest = torch.randn(count, 15, 3, generator=gen) * 0.05
    return Gaussians(means, g.log_scales[src] + np.log(0.6), g.quats[src], g.opacity_logits[src], g.sh_dc[src], rest)


def upsample_points(xyz: np.ndarray, rgb: np.ndarray, count: int, shift: np.ndarray, rng: np.random.Generator):
    both = np.concatenate([xyz, xyz + shift.astype(np.float32)])
    idx = np.arange(count) % len(both)
    jitter = rng.normal(0.0, 0.02, size=(count, 3)).astype(np.float32)  # 2 cm, a LiDAR's range noise
    return both[idx] + jitter, np.concatenate([rgb, rgb])[idx]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--gaussians", type=int, default=5_000_000)
    ap.add_argument("--points", type=int, default=20_000_000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    settings = {"gaussians": a.gaussians, "points": a.points, "seed": a.seed, "block_shift_m": BLOCK_SHIFT}
    marker = a.out / MARKER
    if marker.is_file() and json.loads(marker.read_text()) == settings:
        print(f"{a.out}: up to date")
        return
    if a.out.exists() and any(a.out.iterdir()) and not marker.is_file():
        raise SystemExit(f"{a.out}: a non-empty folder this script did not write; choose another --out")
    base = make_demo_scene(a.out.parent / f".{a.out.name}_base", seed=a.seed, preset="default")
    if a.out.exists():
        shutil.rmtree(a.out)
    shutil.copytree(base, a.out, ignore=shutil.ignore_patterns("3dgs.ply", "raw_pcd.ply", ".demo_scene.json", "*.lod.npz"))
    scene = load_scene(base)
    shift = np.zeros(3)
    shift[2] = BLOCK_SHIFT  # the street runs along x; the copy stands across it, along z (-Y up frame)
    gen = torch.Generator().manual_seed(a.seed)
    upsample_gaussians(Gaussians.load(scene.gaussians_path), a.gaussians, shift, gen).save(a.out / "3dgs.ply")
    pts = read_ply_points(base / "raw_pcd.ply")
    xyz, rgb = upsample_points(pts.xyz, pts.rgb, a.points, shift, np.random.default_rng(a.seed))
    write_ply_points(a.out / "raw_pcd.ply", xyz, rgb)
    meta = json.loads((a.out / "scene_meta.json").read_text())
    meta["name"] = f"stress_{a.gaussians // 1_000_000}m"
    meta["generator"] = {"name": "experiments/render/make_stress_scene.py", **settings}
    with atomic_path(a.out / "scene_meta.json") as tmp:
        tmp.write_text(json.dumps(meta, indent=2))
    with atomic_path(marker) as tmp:
        tmp.write_text(json.dumps(settings))
    lo, hi = xyz.min(0), xyz.max(0)
    print(f"{a.out}: {a.gaussians} Gaussians (SH 3), {a.points} LiDAR points, "
          f"{(hi[0] - lo[0]) * (hi[2] - lo[2]):.0f} m2 footprint ({hi[0] - lo[0]:.1f} x {hi[2] - lo[2]:.1f} m)")


if __name__ == "__main__":
    main()
