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

import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import trimesh
from PIL import Image

from wanderland_nav.atomic import atomic_path, atomic_write_json, atomic_write_text
from wanderland_nav.cache import json_digest, read_record
from wanderland_nav.geometry import nav_from_scene_rotation, rotmat_to_quat
from wanderland_nav.render.gaussians import Gaussians
from wanderland_nav.scene.colmap import (
    ColmapCamera,
    ColmapImage,
    ColmapModel,
    ColmapPoints3D,
    rotmat_to_qvec,
    write_images_bin,
    write_model,
)
from wanderland_nav.scene.pointcloud import write_ply_points

from . import capture, lidar, splats, views
from .layout import Layout, build_layout
from .raycast import RayCaster
from .textures import MATERIALS

GENERATOR_VERSION = 1
UP_AXIS = "-y"
MARKER = ".demo_scene.json"
DEPTH_SCALE = 1000.0  # depth PNG units per metre (uint16 millimetres, 0 = no hit)


@dataclass(frozen=True)
class DemoPreset:
    """Sizes of one build. `tiny` keeps the layout and trajectory, with far fewer samples everywhere."""

    image_size: int  # square pinhole images, 90 deg field of view
    frame_spacing: float  # metres between stereo frames on the training loops
    val_spacing: float  # metres between stereo frames on the extrapolation path
    scan_spacing: float  # metres between LiDAR scans along every path
    lidar_rays: int  # beams per scan
    lidar_range: float  # metres
    lidar_noise: float  # metres, range noise sigma
    splat_spacing: float  # metres between Gaussian centres on a surface
    splat_range: float  # Gaussians only within this distance of the trajectory
    colmap_voxel: float  # points3D = LiDAR cloud thinned to one point per voxel of this size


PRESETS = {
    "default": DemoPreset(image_size=256, frame_spacing=1.5, val_spacing=2.0, scan_spacing=0.4, lidar_rays=2500,
                          lidar_range=30.0, lidar_noise=0.01, splat_spacing=0.12, splat_range=16.0, colmap_voxel=0.3),
    "tiny": DemoPreset(image_size=64, frame_spacing=6.0, val_spacing=8.0, scan_spacing=1.0, lidar_rays=800,
                       lidar_range=20.0, lidar_noise=0.01, splat_spacing=0.35, splat_range=12.0, colmap_voxel=0.5),
}


def scene_from_nav() -> np.ndarray:
    """`[3, 3]` rotation taking the generator's Z-up frame to the written -Y-up scene frame."""
    return nav_from_scene_rotation(UP_AXIS).T


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
    out = Path(out_dir)
    key = _args_hash(seed, preset)
    marker = out / MARKER
    if marker.is_file():
        if (read_record(marker) or {}).get("args_hash") == key:
            return out
    elif out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out}: exists and is not a demo scene (no {MARKER}); refusing to overwrite it")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.building-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _build(tmp, seed, preset, key, timings if timings is not None else {})
        if out.exists():
            old = out.parent / f".{out.name}.old-{os.getpid()}"
            os.replace(out, old)
            os.replace(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


# --------------------------------------------------------------------------- the build


def _build(root: Path, seed: int, preset_name: str, key: str, timings: dict) -> None:
    p = PRESETS[preset_name]
    S = scene_from_nav()
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + now - clock
        clock = now

    layout = build_layout(seed)
    caster = RayCaster(layout.vertices, layout.faces)
    lap("layout")
    rig = capture.make_rig(p.frame_spacing, seed, p.val_spacing)
    T_nav, sides, frame = capture.stereo_cameras(rig)
    K = capture.intrinsics(p.image_size)
    names = [f"{s}/{f:05d}.png" for s, f in zip(sides, frame)]
    split = rig.split[frame]
    rgb, depth, mask, seen_img = views.render_views(caster, layout, T_nav, K, p.image_size, p.image_size, seed)
    lap("images")
    scans = [capture.sample_path(path, p.scan_spacing)[0] for path in capture.PATHS]
    sensors = np.concatenate(scans) + np.array([0.0, 0.0, lidar.SENSOR_ABOVE_RIG])
    pattern = lidar.ScanPattern(rays=p.lidar_rays)
    xyz, col, _exact, seen_lidar = lidar.scan(caster, layout, sensors, pattern, p.lidar_range, p.lidar_noise, seed)
    lap("lidar")
    sp = splats.make_splats(layout, np.union1d(seen_img, seen_lidar), rig.position, p.splat_spacing, p.splat_range, seed)
    lap("splats")

    T_scene = np.tile(np.eye(4), (len(T_nav), 1, 1))
    T_scene[:, :3, :3] = S @ T_nav[:, :3, :3]
    T_scene[:, :3, 3] = T_nav[:, :3, 3] @ S.T
    _write_images(root, names, rgb, depth, mask)
    lap("write_images")
    _write_colmap(root, names, split, T_scene, K, p, xyz @ S.T, col)
    for s in ("train", "val"):
        atomic_write_text(root / "nvs_split" / f"{s}.txt", "".join(n + "\n" for n, sp_ in zip(names, split) if sp_ == s))
    _write_transforms(root, names, split, T_scene, K, p.image_size)
    write_ply_points(root / "raw_pcd.ply", (xyz @ S.T).astype(np.float32), col)
    _write_splats(root / "3dgs.ply", sp, S)
    _write_gt_mesh(root / "gt_mesh.ply", layout, S)
    lap("write_geometry")
    meta = {
        "name": f"demo_block_s{seed}" + ("" if preset_name == "default" else f"_{preset_name}"),
        "up_axis": UP_AXIS,
        "environment": "mixed",
        "indoor_regions": layout.indoor_regions,
        "generator": {
            "name": "wanderland_nav.scene.demo", "version": GENERATOR_VERSION, "seed": seed, "preset": preset_name,
            "settings": asdict(p), "args_hash": key, "raycast_backend": caster.backend,
            "frame": "v1 COLMAP frame, -Y up; nav = nav_from_scene_rotation('-y') @ p_scene is the generator's Z-up frame",
            "depth": {"format": "png16", "units_per_metre": DEPTH_SCALE, "kind": "z-depth along the optical axis",
                      "invalid": 0},
            "images_mask": "255 where a ray hit geometry, 0 for sky",
            "counts": {"images": len(names), "train_images": int((split == "train").sum()),
                       "val_images": int((split == "val").sum()), "lidar_points": int(len(xyz)),
                       "lidar_scans": int(len(sensors)), "gaussians": int(len(sp.means)),
                       "gt_mesh_faces": int(len(layout.faces))},
            "materials": list(MATERIALS),
        },
    }
    atomic_write_json(root / "scene_meta.json", meta)
    atomic_write_json(root / MARKER, {"args_hash": key, "seed": seed, "preset": preset_name,
                                      "version": GENERATOR_VERSION})
    lap("write_meta")


# --------------------------------------------------------------------------- writers (scene frame)


def _save_png(path: Path, arr: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        Image.fromarray(arr).save(tmp, format="PNG", compress_level=1)


def _write_images(root: Path, names, rgb, depth, mask) -> None:
    """`images/`, `images_mask/`, `depth/` (uint16 mm PNG), one file per camera, same relative names."""
    dmm = np.round(depth.astype(np.float64) * DEPTH_SCALE)
    dmm = np.where(dmm > 65535, 0, dmm).astype(np.uint16)
    for i, n in enumerate(names):
        _save_png(root / "images" / n, rgb[i])
        _save_png(root / "images_mask" / n, mask[i])
        _save_png(root / "depth" / n, dmm[i])


def _write_colmap(root: Path, names, split, T_scene, K, p: DemoPreset, xyz_scene, col) -> None:
    """`sparse/0/{cameras,images,points3D}.bin` with the training views, and the extrapolation
    (val) views in `sparse/0/images_val.bin`, as the real v1 release keeps them."""
    cam = ColmapCamera(1, "PINHOLE", p.image_size, p.image_size, np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))
    images = {}
    for i, (n, T) in enumerate(zip(names, T_scene)):
        R = T[:3, :3].T  # cam_from_world
        images[i + 1] = ColmapImage(i + 1, rotmat_to_qvec(R), -R @ T[:3, 3], 1, n)
    # points3D: the LiDAR cloud thinned to one point per voxel (first in scan order), no tracks
    vox = np.floor(xyz_scene / p.colmap_voxel).astype(np.int64)
    vox -= vox.min(0)
    lin = (vox[:, 0] * (vox[:, 1].max() + 1) + vox[:, 1]) * (vox[:, 2].max() + 1) + vox[:, 2]
    _, first = np.unique(lin, return_index=True)
    first = np.sort(first)
    m = len(first)
    pts = ColmapPoints3D(np.arange(1, m + 1, dtype=np.int64), xyz_scene[first].astype(np.float64), col[first],
                         np.zeros(m), np.zeros(m + 1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32))
    train = {k: im for k, im in images.items() if split[k - 1] == "train"}
    val = {k: im for k, im in images.items() if split[k - 1] == "val"}
    write_model(root / "sparse" / "0", ColmapModel({1: cam}, train, pts), ext=".bin")
    write_images_bin(root / "sparse" / "0" / "images_val.bin", val)


def _write_transforms(root: Path, names, split, T_scene, K, size: int) -> None:
    """nerfstudio-style `transforms.json`: `transform_matrix` is camera-to-world with OpenGL camera axes
    (x right, y up, z backward), in the scene frame, as nerfstudio writes it."""
    gl = np.diag([1.0, -1.0, -1.0, 1.0])
    frames = [{"file_path": f"images/{n}", "mask_path": f"images_mask/{n}", "depth_file_path": f"depth/{n}",
               "split": str(s), "transform_matrix": np.round(T @ gl, 9).tolist()} for n, s, T in zip(names, split, T_scene)]
    atomic_write_json(root / "transforms.json", {
        "camera_model": "PINHOLE", "fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]), "cx": float(K[0, 2]),
        "cy": float(K[1, 2]), "w": int(size), "h": int(size), "k1": 0.0, "k2": 0.0, "k3": 0.0, "k4": 0.0,
        "camera_convention": "opengl", "frames": frames})


def _write_splats(path: Path, sp: "splats.SplatSet", S: np.ndarray) -> None:
    R = torch.from_numpy(S @ sp.rotations)  # [N, 3, 3] scene frame
    g = Gaussians(
        means=torch.from_numpy(sp.means @ S.T).float(),
        log_scales=torch.from_numpy(sp.log_scales).float(),
        quats=rotmat_to_quat(R).float(),
        opacity_logits=torch.from_numpy(sp.opacity_logits).float(),
        sh_dc=torch.from_numpy(sp.sh_dc).float(),
        sh_rest=torch.zeros(len(sp.means), 0, 3),
    )
    g.save(path)


def _write_gt_mesh(path: Path, layout: Layout, S: np.ndarray) -> None:
    """Ground-truth mesh (evaluation only), scene frame, face colours = mean albedo of each material."""
    from . import textures

    probe = np.linspace(0.0, 40.0, 257)
    pts = np.stack([probe, probe * 0.37, np.full_like(probe, 1.0)], -1)
    mean = np.stack([textures.albedo(np.full(len(probe), m), pts, np.tile([0.0, 0.0, 1.0], (len(probe), 1)),
                                     np.full(len(probe), 0.05), 0, layout.car_color).mean(0)
                     for m in range(len(MATERIALS))])
    fc = np.concatenate([np.round(mean[layout.face_material] * 255), np.full((len(layout.faces), 1), 255)], 1)
    mesh = trimesh.Trimesh(layout.vertices @ S.T, layout.faces, face_colors=fc.astype(np.uint8), process=False)
    with atomic_path(path) as tmp:
        tmp.write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary"))


__all__ = ["make_demo_scene", "PRESETS", "DemoPreset", "UP_AXIS", "scene_from_nav", "GENERATOR_VERSION"]
