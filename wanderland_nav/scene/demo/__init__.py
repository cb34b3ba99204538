"""The procedural demo scene: a small Wanderland-v1-style capture of a synthetic urban block.

`make_demo_scene(out_dir, seed=0, preset="default")` writes, in the v1 folder layout and in the
v1 COLMAP frame (-Y up), everything a real scene has: ray-cast pinhole images with depth and
masks, a COLMAP model, NVS train/val splits, a LiDAR-like `raw_pcd.ply`, an INRIA `3dgs.ply`,
`transforms.json`, plus the ground-truth mesh and `scene_meta.json` (up axis, indoor region).
Geometry is generated in a Z-up frame (`layout.py`; it *is* the nav frame of a "-y" scene) and
rotated into the scene frame only when written, so every consumer exercises the up-axis path.

The build happens in a temporary sibling folder that is renamed into place at the end, and a
marker file with the hash of the arguments makes reruns return at once; the same seed and
preset give byte-identical files.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import json_digest

from .capture import PATHS
from .layout import build_layout
from .pipeline import UP_AXIS, DemoPreset, build_in_place, scene_from_nav, write_capture

GENERATOR_VERSION = 1
MARKER = ".demo_scene.json"


PRESETS = {
    "default": DemoPreset(image_size=256, frame_spacing=1.5, val_spacing=2.0, scan_spacing=0.4, lidar_rays=2500,
                          lidar_range=30.0, lidar_noise=0.01, splat_spacing=0.12, splat_range=16.0, colmap_voxel=0.3),
    "tiny": DemoPreset(image_size=64, frame_spacing=6.0, val_spacing=8.0, scan_spacing=1.0, lidar_rays=800,
                       lidar_range=20.0, lidar_noise=0.01, splat_spacing=0.35, splat_range=12.0, colmap_voxel=0.5),
}


def _args_hash(seed: int, preset: str) -> str:
    return json_digest({"seed": seed, "preset": preset, "settings": asdict(PRESETS[preset]),
                        "version": GENERATOR_VERSION})


def make_demo_scene(out_dir, seed: int = 0, preset: str = "default", *, timings: dict | None = None) -> Path:
    """Write the demo scene to `out_dir` (v1 layout, -Y up) and return its path.

    Idempotent: if `out_dir` already holds this (seed, preset) build it returns at once; a
    different build there is replaced whole (derived files such as a stale navmesh go with it).
    A non-empty folder that is not a demo scene is never touched. `timings`, if given, is filled
    with seconds per stage.
    """
    if preset not in PRESETS:
        raise ValueError(f"make_demo_scene: preset must be one of {sorted(PRESETS)}, got {preset!r}")
    seed = int(seed)
    key = _args_hash(seed, preset)
    timings = timings if timings is not None else {}
    return build_in_place(out_dir, key, MARKER, "demo scene", lambda tmp: _build(tmp, seed, preset, key, timings))


def _build(root: Path, seed: int, preset_name: str, key: str, timings: dict) -> None:
    layout = build_layout(seed)
    gen = write_capture(root, layout, PATHS, PRESETS[preset_name], seed, timings)
    meta = {
        "name": f"demo_block_s{seed}" + ("" if preset_name == "default" else f"_{preset_name}"),
        "up_axis": UP_AXIS,
        "environment": "mixed",
        "indoor_regions": layout.indoor_regions,
        "generator": {"name": "wanderland_nav.scene.demo", "version": GENERATOR_VERSION, "seed": seed,
                      "preset": preset_name, "settings": gen.pop("settings"), "args_hash": key, **gen},
    }
    atomic_write_json(root / "scene_meta.json", meta)
    atomic_write_json(root / MARKER, {"args_hash": key, "seed": seed, "preset": preset_name,
                                      "version": GENERATOR_VERSION})


__all__ = ["make_demo_scene", "PRESETS", "DemoPreset", "UP_AXIS", "scene_from_nav", "GENERATOR_VERSION"]
