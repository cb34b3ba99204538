"""Degraded copies of LiDAR-only scenes (v2 `lidar/*.bin` scans + `lidar/poses.txt`, e.g. the KITTI street).

Such a scene has no camera model: its capture trajectory is the LiDAR's (`poses.txt`, world_from_sensor
per scan) and every return is registered by the pose of the scan it belongs to. So the pose-error field
(`poses.PoseCorrection`, drawn on the sensor positions) moves each scan rigidly with its own pose:

    world' = s (R_i (T_i p - c_i) + c_i + t_i) = (R_i R_sensor_i) (s p) + s (c_i + t_i)

i.e. the new pose is `corr.apply_poses(T_i)` and the scan's own points are multiplied by the scale s
(a metric sensor seen through a non-metric trajectory), as is `lidar_min_range` in `scene_meta.json`
(`build._meta`).
Holes and dropped fragments are cut on the grounded world positions of all scans together and then
removed from each scan. A scene with a `lidar_splat` (`scene/lidar_splat.py`, its settings in
`scene_meta.json`) gets its splat rebuilt from the degraded scans, so camera and collision geometry carry
the same error. Splat-derived collision geometry is refused: a LiDAR splat's surfels ARE the LiDAR returns
(fusing their rendered depth returns the LiDAR surface, not a video-3DGS's photometric one), and there are
no camera poses to render it from (`splat_mesh`, `video3dgs`: not applicable).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.scene.lidar_splat import META_KEY, LidarSplatSettings, splat_from_scans
from wanderland_nav.scene.pointcloud import read_kitti_bin

from .damage import fragment_mask, hole_mask, horizontal_xy
from .poses import PoseCorrection
from .spec import DegradeSpec


def lidar_scans(src: Path) -> list[Path]:
    """The KITTI `.bin` scans of a LiDAR-only scene, in name order (the order of `poses.txt` lines)."""
    files = sorted(p for p in (src / "lidar").iterdir() if p.is_file() and p.suffix.lower() in
                   (".bin", ".ply", ".las", ".laz"))
    other = [p.name for p in files if p.suffix.lower() != ".bin"]
    if other:
        raise ValueError(f"{src / 'lidar'}: degraded LiDAR-only builds read KITTI .bin scans; {other} are not")
    return files


def write_lidar_only(src: Path, dst: Path, scene, spec: DegradeSpec, corr: PoseCorrection,
                     rng: np.random.Generator) -> dict:
    """Write `dst/lidar/*.bin`, `dst/lidar/poses.txt` and copy the other top-level files; -> figures."""
    if spec.geometry == "splats":
        raise ValueError(f"{src}: preset {spec.name!r} is not applicable to a LiDAR-only scene: splat-derived "
                         "collision geometry needs a photometric 3D Gaussian splat rendered from camera poses "
                         "(a lidar_splat's surfels are the LiDAR returns themselves)")
    files = lidar_scans(src)
    T = np.asarray(scene.lidar_poses, dtype=np.float64)  # [K,4,4] world_from_sensor
    scans = [read_kitti_bin(f) for f in files]  # [N_i,4] float32 x y z intensity, sensor frame
    world = np.concatenate([s[:, :3].astype(np.float64) @ T[i, :3, :3].T + T[i, :3, 3] for i, s in enumerate(scans)])
    xy = horizontal_xy(world, scene.up_axis)
    keep_h, n_holes = hole_mask(xy, rng, spec.hole_rate_per_100m2, spec.hole_radius)
    keep_f, n_tiles = fragment_mask(xy, rng, spec.fragment_drop_rate, spec.fragment_tile)
    keep = np.split(keep_h & keep_f, np.cumsum([len(s) for s in scans])[:-1])
    (dst / "lidar").mkdir(parents=True)
    for f, scan, k in zip(files, scans, keep):
        out = scan[k].copy()
        out[:, :3] *= np.float32(corr.scale)
        with atomic_path(dst / "lidar" / f.name) as tmp:
            out.astype("<f4").tofile(tmp)
    new_T = corr.apply_poses(T)
    with atomic_path(dst / "lidar" / "poses.txt") as tmp:
        np.savetxt(tmp, new_T[:, :3, :].reshape(len(T), 12), fmt="%.9e")
    splat = _rebuild_splat(scene, [s[k] * np.float32([corr.scale] * 3 + [1]) for s, k in zip(scans, keep)], new_T,
                           corr.scale, dst) if META_KEY in scene.meta else {}
    for p in sorted(src.iterdir()):  # e.g. other metadata; prepared artefacts and plots are rebuilt / dropped
        if p.is_file() and p.name != "scene_meta.json" and p.suffix.lower() in (".json", ".txt", ".yaml") \
                and not p.name.startswith(("collision_mesh", "navmesh", "episodes", ".")):
            shutil.copy2(p, dst / p.name)
    return {"points_in": int(len(world)), "points_kept": int(sum(k.sum() for k in keep)), "holes": n_holes,
            "fragments_dropped": n_tiles, "lidar_points": int(len(world)), "scans": len(files), **splat}


def _rebuild_splat(scene, scans: list[np.ndarray], world_from_sensor: np.ndarray, scale: float, dst: Path) -> dict:
    """The source's `lidar_splat` rebuilt from the degraded scans and poses with its settings scaled by the
    world's scale, written to `dst/3dgs.ply`: the camera then sees exactly the misregistered geometry (drift's
    ghost layers) and the metric error (scale) the collision mesh has. -> figures (prefixed `splat_`)."""
    block = scene.meta[META_KEY]
    st = LidarSplatSettings(**block["settings"]).scaled(scale)
    min_range = float(block["figures"]["min_range_m"]) * scale
    g, figures = splat_from_scans(scans, world_from_sensor, min_range, st)
    g.save(dst / "3dgs.ply")
    return {f"splat_{k}": v for k, v in figures.items()}
