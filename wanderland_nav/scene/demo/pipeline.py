"""The capture pipeline every procedural scene shares: a textured triangle soup (`layout.Layout`) and its
capture paths -> a scene folder in the Wanderland v1 layout (-Y up).

`write_capture` ray-casts the stereo images, depth and masks along the paths, scans the LiDAR cloud
from the same walk, puts flat Gaussians on the seen surfaces and writes every product (COLMAP model,
NVS split, `raw_pcd.ply`, `3dgs.ply`, `transforms.json`, `gt_mesh.ply`, `scene_meta.json`).
`build_in_place` wraps a build with what makes it safe to rerun: the build goes to a temporary
sibling folder renamed into place at the end, a marker file with the hash of the arguments makes a
rerun return at once, a different build there is replaced whole, and a folder the generator did not
write is refused. The demo block (`make_demo_scene`) and the districts (`scene.district`) both go
through here, so the same seed and sizes give byte-identical files for both.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import trimesh
from PIL import Image

from wanderland_nav.atomic import atomic_path, atomic_write_json, atomic_write_text
from wanderland_nav.cache import read_record
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
from .layout import Layout
from .raycast import RayCaster
from . import textures
from .textures import MATERIALS

UP_AXIS = "-y"
DEPTH_SCALE = 1000.0  # depth PNG units per metre (uint16 millimetres, 0 = no hit)


@dataclass(frozen=True)
class DemoPreset:
    """Sizes of one build (the demo's presets, the districts' sizes)."""

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


def scene_from_nav() -> np.ndarray:
    """`[3, 3]` rotation taking the generator's Z-up frame to the written -Y-up scene frame."""
    return nav_from_scene_rotation(UP_AXIS).T


def build_in_place(out_dir, key: str, marker: str, what: str, build: Callable[[Path], None]) -> Path:
    """Run `build(tmp)` into a temporary sibling of `out_dir` and rename it into place; idempotent by `key`.

    `out_dir` holding `marker` with this `key` returns at once; with another key it is replaced whole
    (derived files such as a stale navmesh go with it); a non-empty folder without `marker` is refused."""
    out = Path(out_dir)
    m = out / marker
    if m.is_file():
        if (read_record(m) or {}).get("args_hash") == key:
            return out
    elif out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out}: exists and is not a {what} (no {marker}); refusing to overwrite it")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.building-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        build(tmp)
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


def write_capture(root: Path, layout: Layout, paths, p: DemoPreset, seed: int, timings: dict, *,
                  sh_degree: int = 0) -> dict:
    """Capture `layout` along `paths` (`capture.CapturePath`s) with sizes `p` and write every product but
    `scene_meta.json` into `root`. Returns the `generator` block's common fields for `scene_meta.json`
    (counts, frame and file conventions). `sh_degree` > 0 writes that many SH bands (all zero beyond the
    DC term: the shading is view-independent, so that is the exact fit)."""
    if layout.walk_height is None:
        raise ValueError("write_capture: the layout has no walk_height (the walked surface the rig follows)")
    S = scene_from_nav()
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + now - clock
        clock = now

    caster = RayCaster(layout.vertices, layout.faces)
    lap("layout")
    rig = capture.make_rig(p.frame_spacing, seed, p.val_spacing, paths, layout.walk_height)
    T_nav, sides, frame = capture.stereo_cameras(rig)
    K = capture.intrinsics(p.image_size)
    names = [f"{s}/{f:05d}.png" for s, f in zip(sides, frame)]
    split = rig.split[frame]
    rgb, depth, mask, seen_img = views.render_views(caster, layout, T_nav, K, p.image_size, p.image_size, seed)
    lap("images")
    _write_images(root, names, rgb, depth, mask)
    del rgb, depth, mask  # the views are on disk: not held through the LiDAR and splat stages
    lap("write_images")
    scans = [capture.sample_path(path, p.scan_spacing, layout.walk_height)[0] for path in paths]
    sensors = np.concatenate(scans) + np.array([0.0, 0.0, lidar.SENSOR_ABOVE_RIG])
    pattern = lidar.ScanPattern(rays=p.lidar_rays)
    xyz, col, _exact, seen_lidar = lidar.scan(caster, layout, sensors, pattern, p.lidar_range, p.lidar_noise, seed)
    lap("lidar")
    sp = splats.make_splats(layout, np.union1d(seen_img, seen_lidar), rig.position, p.splat_spacing, p.splat_range, seed)
    lap("splats")

    T_scene = np.tile(np.eye(4), (len(T_nav), 1, 1))
    T_scene[:, :3, :3] = S @ T_nav[:, :3, :3]
    T_scene[:, :3, 3] = T_nav[:, :3, 3] @ S.T
    _write_colmap(root, names, split, T_scene, K, p, xyz @ S.T, col)
    for s in ("train", "val"):
        atomic_write_text(root / "nvs_split" / f"{s}.txt", "".join(n + "\n" for n, sp_ in zip(names, split) if sp_ == s))
    _write_transforms(root, names, split, T_scene, K, p.image_size)
    write_ply_points(root / "raw_pcd.ply", (xyz @ S.T).astype(np.float32), col)
    _write_splats(root / "3dgs.ply", sp, S, sh_degree)
    _write_gt_mesh(root / "gt_mesh.ply", layout, S)
    lap("write_geometry")
    return {
        "settings": asdict(p), "raycast_backend": caster.backend,
        "frame": "v1 COLMAP frame, -Y up; nav = nav_from_scene_rotation('-y') @ p_scene is the generator's Z-up frame",
        "depth": {"format": "png16", "units_per_metre": DEPTH_SCALE, "kind": "z-depth along the optical axis",
                  "invalid": 0},
        "images_mask": "255 where a ray hit geometry, 0 for sky",
        "counts": {"images": len(names), "train_images": int((split == "train").sum()),
                   "val_images": int((split == "val").sum()), "lidar_points": int(len(xyz)),
                   "lidar_scans": int(len(sensors)), "gaussians": int(len(sp.means)),
                   "gt_mesh_faces": int(len(layout.faces))},
        "materials": list(MATERIALS),
    }


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


def _write_splats(path: Path, sp: "splats.SplatSet", S: np.ndarray, sh_degree: int = 0) -> None:
    R = torch.from_numpy(S @ sp.rotations)  # [N, 3, 3] scene frame
    g = Gaussians(
        means=torch.from_numpy(sp.means @ S.T).float(),
        log_scales=torch.from_numpy(sp.log_scales).float(),
        quats=rotmat_to_quat(R).float(),
        opacity_logits=torch.from_numpy(sp.opacity_logits).float(),
        sh_dc=torch.from_numpy(sp.sh_dc).float(),
        sh_rest=torch.zeros(1, (sh_degree + 1) ** 2 - 1, 3).expand(len(sp.means), -1, -1),  # one zero row, not N
    )
    g.save(path)


def _write_gt_mesh(path: Path, layout: Layout, S: np.ndarray) -> None:
    """Ground-truth mesh (evaluation only), scene frame, face colours = mean albedo of each material."""

    probe = np.linspace(0.0, 40.0, 257)
    pts = np.stack([probe, probe * 0.37, np.full_like(probe, 1.0)], -1)
    mean = np.stack([textures.albedo(np.full(len(probe), m), pts, np.tile([0.0, 0.0, 1.0], (len(probe), 1)),
                                     np.full(len(probe), 0.05), 0, layout.car_color).mean(0)
                     for m in range(len(MATERIALS))])
    fc = np.concatenate([np.round(mean[layout.face_material] * 255), np.full((len(layout.faces), 1), 255)], 1)
    mesh = trimesh.Trimesh(layout.vertices @ S.T, layout.faces, face_colors=fc.astype(np.uint8), process=False)
    with atomic_path(path) as tmp:
        tmp.write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary"))


