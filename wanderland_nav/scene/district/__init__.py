"""Procedural urban districts of the paper's scene size: a new street layout for every seed.

`make_district(out_dir, seed=0, size="small")` writes a 5,000-10,000 m^2 district (`layout.py`: streets
with junctions, crossings and kerbs, blocks of buildings with at least one that can be entered, plazas
on terraces with ramps and stairs, parks, street furniture, parked cars) in the Wanderland v1 folder
layout with every product the demo block has (stereo images with depth and masks along closed capture
loops and extrapolation paths, COLMAP model with points3D, LiDAR cloud, an SH-degree-3 `3dgs.ply`,
`transforms.json`, `gt_mesh.ply`, `scene_meta.json` with the indoor regions and the street graph). The
capture and every writer are the demo's (`scene.demo.pipeline`); only the geometry and the paths differ.

Sizes are settings of the same layout: `small` (tests, smoke runs, the scene sets) and `paper` (the
paper's density: >= 5M Gaussians on the seen surfaces and >= 20M LiDAR points). Idempotent and
deterministic like the demo: the same (seed, size) gives byte-identical files.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import json_digest

from ..demo.pipeline import UP_AXIS, DemoPreset, build_in_place, write_capture
from .layout import District, build_district
import time

GENERATOR_VERSION = 1
MARKER = ".district_scene.json"
SH_DEGREE = 3
#: the paper's episode regime on a district (`scene_meta.json` `episode_sampler`, applied by the episode generator):
#: routes of 5-150 m geodesic over the whole district (the paper's outdoor routes reach >= 100 m) and a share of
#: sampling rounds drawn inside the buildings, so indoor routes exist beside the long outdoor and mixed ones
EPISODE_SAMPLER = {"min_geodesic": 5.0, "max_geodesic": 150.0, "indoor_fraction": 0.15, "max_rounds": 400}

SIZES = {
    "small": DemoPreset(image_size=48, frame_spacing=5.0, val_spacing=8.0, scan_spacing=1.2, lidar_rays=700,
                        lidar_range=25.0, lidar_noise=0.01, splat_spacing=0.4, splat_range=14.0, colmap_voxel=0.5),
    "paper": DemoPreset(image_size=256, frame_spacing=1.0, val_spacing=2.0, scan_spacing=0.25, lidar_rays=5000,
                        lidar_range=40.0, lidar_noise=0.01, splat_spacing=0.055, splat_range=25.0, colmap_voxel=0.2),
}


def _args_hash(seed: int, size: str) -> str:
    return json_digest({"seed": seed, "size": size, "settings": asdict(SIZES[size]), "version": GENERATOR_VERSION,
                        "sh_degree": SH_DEGREE})


def district_summary(d: District) -> dict:
    """What a seed gave: extent, street graph, blocks (the `generator.district` block of `scene_meta.json`)."""
    p = d.plan
    return {"extent_m": [round(p.W, 3), round(p.H, 3)], "area_m2": round(p.W * p.H, 1),
            "street_graph": {"nodes": np.round(p.nodes, 3).tolist(), "edges": [[int(a), int(b), k] for a, b, k in p.edges]},
            "streets": [{"axis": s.axis, "position": round(s.pos, 3), "kind": s.kind,
                         "segments": [[round(a, 3), round(b, 3)] for a, b in s.segments]} for s in p.streets],
            "blocks": [{"rect": [round(v, 3) for v in bl.rect], "kind": k} for bl, k in zip(p.blocks, d.block_kinds)],
            "parked_cars": d.cars, "capture_paths": [{"name": c.name, "split": c.split} for c in d.paths]}


def make_district(out_dir, seed: int = 0, size: str = "small", *, timings: dict | None = None) -> Path:
    """Write the district of `seed` at `size` ("small" | "paper") to `out_dir` (v1 layout, -Y up); returns the path.

    Idempotent: a folder holding this (seed, size) build returns at once; another district build there is
    replaced whole; a non-empty folder that is not a district is never touched. `timings`, if given, is
    filled with seconds per stage."""
    if size not in SIZES:
        raise ValueError(f"make_district: size must be one of {sorted(SIZES)}, got {size!r}")
    seed = int(seed)
    key = _args_hash(seed, size)
    timings = timings if timings is not None else {}
    return build_in_place(out_dir, key, MARKER, "district scene", lambda tmp: _build(tmp, seed, size, key, timings))


def _build(root: Path, seed: int, size: str, key: str, timings: dict) -> None:

    t = time.perf_counter()
    d = build_district(seed)
    timings["district_layout"] = time.perf_counter() - t
    gen = write_capture(root, d.layout, d.paths, SIZES[size], seed, timings, sh_degree=SH_DEGREE)
    meta = {
        "name": f"district_s{seed}_{size}",
        "up_axis": UP_AXIS,
        "environment": "mixed",
        "indoor_regions": d.layout.indoor_regions,
        "episode_sampler": EPISODE_SAMPLER,
        "generator": {"name": "wanderland_nav.scene.district", "version": GENERATOR_VERSION, "seed": seed,
                      "size": size, "settings": gen.pop("settings"), "args_hash": key, "sh_degree": SH_DEGREE, **gen,
                      "district": district_summary(d)},
    }
    atomic_write_json(root / "scene_meta.json", meta)
    atomic_write_json(root / MARKER, {"args_hash": key, "seed": seed, "size": size, "version": GENERATOR_VERSION})


__all__ = ["make_district", "SIZES", "MARKER", "GENERATOR_VERSION", "EPISODE_SAMPLER", "build_district",
           "district_summary"]
