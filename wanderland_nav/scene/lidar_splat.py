"""`lidar_splat`: a 3D Gaussian splat made directly from LiDAR returns, for scenes with no camera images.

Why: every policy here sees camera images rendered from `3dgs.ply`, and a photographic 3DGS is fitted to
posed images. A LiDAR-only capture (the shared KITTI street: Velodyne scans + GICP poses, no images) has
none, so it could not be trained or evaluated in. This builder gives such a scene a splat the renderer can
draw: **not photorealistic** (no image was ever seen; colours are a false-colour code), but geometrically
exact where the LiDAR saw something, so a policy sees the road, kerbs, cars and walls where they are.

One Gaussian per occupied `voxel` (the returns' centroid, v2 frame: +z up, metres):

* **shape**: a surfel in the plane of the local point distribution (PCA over the `neighbours` nearest
  centroids); in-plane sigma = `spacing_scale` x the mean distance to those neighbours (clamped to
  [`min_sigma`, `max_sigma`]), so sparse far rings get wide splats that close the gaps and dense near
  surfaces small ones; sigma along the normal = `flatness` x that (a thin disc, as the demo's surfels);
* **colour** (SH degree 0): near the ground (within `ground_band` of the lowest return in its
  `ground_cell` column) a grey from the LiDAR intensity (bright lane markings on dark asphalt); above
  it a height ramp orange -> blue over `tint_height`, brightened by intensity, so obstacles stand out;
* **opacity** from point density: `opacity_min + (opacity_max - opacity_min) (1 - exp(-n / density_ref))`
  for n returns in the voxel (a single stray return is faint, a wall is solid).

Everything metric is in `LidarSplatSettings`; `settings.scaled(s)` scales it, and the voxel grid is anchored
at the origin, so the splat of a world scaled by s is the splat scaled by s (what `degrade` relies on).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import rotmat_to_quat
from wanderland_nav.render import Gaussians
from wanderland_nav.render.sh import SH_C0
from wanderland_nav.scene.loader import load_scene, visible_files
from wanderland_nav.scene.pointcloud import PointCloudFormatError, read_kitti_bin

META_KEY = "lidar_splat"  # scene_meta.json block: settings and figures of the splat in 3dgs.ply
_METRIC = ("voxel", "crop_radius", "min_sigma", "max_sigma", "ground_cell", "ground_band", "tint_height")
_LOW, _HIGH = np.array([0.85, 0.55, 0.25]), np.array([0.35, 0.55, 0.90])  # height ramp: ground-level -> tall


@dataclass(frozen=True)
class LidarSplatSettings:
    voxel: float = 0.25  # m: one Gaussian per occupied voxel
    crop_radius: float = 25.0  # m: returns farther (horizontally) from every sensor pose are dropped
    neighbours: int = 8  # nearest centroids for the local spacing and plane
    spacing_scale: float = 0.6  # in-plane sigma / mean neighbour distance
    min_sigma: float = 0.04  # m
    max_sigma: float = 0.6  # m
    flatness: float = 0.1  # sigma along the local normal / in-plane sigma
    opacity_min: float = 0.3
    opacity_max: float = 0.97
    density_ref: float = 2.0  # returns per voxel at which opacity reaches ~63 % of its range
    ground_cell: float = 1.0  # m: xy column in which the lowest return is the ground
    ground_band: float = 0.25  # m: returns this close above their column's ground are coloured as ground
    tint_height: float = 4.0  # m: height over which the obstacle colour ramps from orange to blue

    def __post_init__(self):
        positive = [f.name for f in dataclasses.fields(self) if f.name not in ("neighbours",)]
        bad = [n for n in positive if not (np.isfinite(getattr(self, n)) and getattr(self, n) > 0)]
        if bad or self.neighbours < 3 or not (0 < self.opacity_min <= self.opacity_max < 1) \
                or self.min_sigma > self.max_sigma:
            rule = "neighbours >= 3, 0 < opacity_min <= opacity_max < 1, min_sigma <= max_sigma"
            raise ValueError(f"LidarSplatSettings: invalid field(s) {bad or rule} "
                             f"(metric fields > 0; {rule}) in {dataclasses.asdict(self)}")

    def scaled(self, s: float) -> "LidarSplatSettings":
        """The same settings for a world scaled by `s` (every metric field times s)."""
        return dataclasses.replace(self, **{k: getattr(self, k) * s for k in _METRIC})


def lidar_colours(intensity: np.ndarray, height: np.ndarray, st: LidarSplatSettings) -> np.ndarray:
    """[M] intensity in [0, 1], [M] height above the column's ground (m) -> [M, 3] RGB in [0, 1]."""
    i = np.clip(intensity, 0.0, 1.0)[:, None]
    grey = np.repeat(0.2 + 0.7 * i, 3, axis=1)
    t = np.clip((height - st.ground_band) / st.tint_height, 0.0, 1.0)[:, None]
    tint = ((1 - t) * _LOW + t * _HIGH) * (0.55 + 0.45 * i)
    return np.where((height > st.ground_band)[:, None], tint, grey)


def _voxel_means(xyz: np.ndarray, values: np.ndarray, size: float):
    """Group [N,3] points by `size` voxels -> (centroids [M,3], mean values [M], counts [M])."""
    _, inv, counts = np.unique(np.floor(xyz / size).astype(np.int64), axis=0, return_inverse=True,
                               return_counts=True)
    inv = inv.ravel()
    cent = np.stack([np.bincount(inv, xyz[:, d]) for d in range(3)], axis=1) / counts[:, None]
    return cent, np.bincount(inv, values) / counts, counts


def _column_height(xyz: np.ndarray, cell: float) -> np.ndarray:
    """[M] height of each point above the lowest point of its `cell` x `cell` column (the local ground)."""
    _, inv = np.unique(np.floor(xyz[:, :2] / cell).astype(np.int64), axis=0, return_inverse=True)
    inv = inv.ravel()
    low = np.full(inv.max() + 1, np.inf)
    np.minimum.at(low, inv, xyz[:, 2])
    return xyz[:, 2] - low[inv]


def _surfel_frames(cent: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean distance to the k nearest other centroids [M] and a right-handed frame [M,3,3] whose columns
    are the local principal axes, major first, the normal (least variance) last."""
    dist, idx = cKDTree(cent).query(cent, k=k + 1)  # [M, k+1], self first
    nb = cent[idx] - cent[idx].mean(axis=1, keepdims=True)  # [M, k+1, 3]
    _, vecs = np.linalg.eigh(np.einsum("mki,mkj->mij", nb, nb))  # ascending eigenvalues
    frame = vecs[:, :, ::-1].copy()
    frame[np.linalg.det(frame) < 0, :, 2] *= -1
    return dist[:, 1:].mean(axis=1), frame


def splat_from_points(xyz: np.ndarray, intensity: np.ndarray, sensor_xyz: np.ndarray,
                      st: LidarSplatSettings = LidarSplatSettings()):
    """World returns [N,3] (+z up, m) with intensity [N] (>= 0; normalised by its 99th percentile) and the
    sensor positions [K,3] -> (`Gaussians` [M], figures). See the module docstring for every rule."""
    xyz = np.asarray(xyz, dtype=np.float64)
    near = np.linalg.norm(xyz[:, None, :2] - np.asarray(sensor_xyz, np.float64)[None, :, :2], axis=-1).min(1) \
        <= st.crop_radius
    xyz, inten = xyz[near], np.asarray(intensity, np.float64)[near]
    ref = np.quantile(inten, 0.99) if len(inten) else 0.0
    cent, mean_i, counts = _voxel_means(xyz, inten / ref if ref > 0 else inten, st.voxel)
    if len(cent) <= st.neighbours:
        raise ValueError(f"lidar splat: {len(cent)} occupied voxels within {st.crop_radius} m of the sensor path, "
                         f"need more than neighbours={st.neighbours}")
    spacing, frame = _surfel_frames(cent, st.neighbours)
    sigma = np.clip(st.spacing_scale * spacing, st.min_sigma, st.max_sigma)
    rgb = lidar_colours(mean_i, _column_height(cent, st.ground_cell), st)
    alpha = st.opacity_min + (st.opacity_max - st.opacity_min) * (1 - np.exp(-counts / st.density_ref))
    f64 = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))  # noqa: E731
    g = Gaussians(means=f64(cent).float(),
                  log_scales=f64(np.log(sigma[:, None] * [1.0, 1.0, st.flatness])).float(),
                  quats=rotmat_to_quat(f64(frame)).float(),
                  opacity_logits=f64(np.log(alpha / (1 - alpha))).float(),
                  sh_dc=f64((rgb - 0.5) / SH_C0).float(), sh_rest=torch.zeros(len(cent), 0, 3))
    figures = {"returns_used": int(len(xyz)), "returns_cropped": int((~near).sum()), "gaussians": int(len(cent)),
               "sigma_median_m": float(np.median(sigma)), "opacity_median": float(np.median(alpha))}
    return g, figures


def splat_from_scans(scans: list[np.ndarray], world_from_sensor: np.ndarray, min_range: float,
                     st: LidarSplatSettings = LidarSplatSettings()):
    """KITTI-style scans ([N_i, 4] x y z intensity, sensor frame) with poses [K,4,4] -> (Gaussians, figures).
    Returns within `min_range` (horizontal, sensor frame) are the capture platform and are dropped."""
    T = np.asarray(world_from_sensor, dtype=np.float64)
    kept = [s[np.linalg.norm(s[:, :2], axis=1) >= min_range] for s in scans]
    xyz = np.concatenate([s[:, :3].astype(np.float64) @ T[i, :3, :3].T + T[i, :3, 3] for i, s in enumerate(kept)])
    return splat_from_points(xyz, np.concatenate([s[:, 3] for s in kept]), T[:, :3, 3], st)


def read_scans(root: Path) -> list[np.ndarray]:
    """The KITTI `.bin` scans in `root/lidar` in the loader's order ([N_i, 4], the order of `poses.txt`);
    refuses other files and bad records."""
    files = [p for p in visible_files(Path(root) / "lidar") if p.suffix.lower() != ".txt"]
    if not files or any(p.suffix.lower() != ".bin" for p in files):
        raise WanderlandInputError(f"{Path(root) / 'lidar'}: a LiDAR splat is built from KITTI .bin scans "
                                   f"(x y z intensity); found {[p.name for p in files] or 'none'}")
    scans = []
    for f in files:
        try:  # refuses non-finite points and negative intensity, naming the file
            scans.append(read_kitti_bin(f))
        except PointCloudFormatError as e:
            raise WanderlandInputError(str(e)) from None
    return scans


def write_lidar_splat(root, st: LidarSplatSettings = LidarSplatSettings()) -> dict:
    """Build the splat of LiDAR-only scene folder `root` (`lidar/*.bin` + `lidar/poses.txt`) into
    `root/3dgs.ply` and record settings and figures under `lidar_splat` in `scene_meta.json`; -> figures."""
    root = Path(root)
    scene = load_scene(root)
    if scene.lidar_poses is None:
        raise WanderlandInputError(f"{root / 'lidar' / 'poses.txt'}: missing; a LiDAR splat needs each scan's "
                                   "world_from_sensor pose (KITTI 3x4 per line)")
    if scene.up_axis != "+z":
        raise WanderlandInputError(f"{root / 'scene_meta.json'}: field up_axis is {scene.up_axis!r}; the LiDAR "
                                   "splat builder reads v2 scans with +z up")
    min_range = float((scene.meta.get("lidar_filter") or {}).get("min_range_m", 0.0))
    g, figures = splat_from_scans(read_scans(root), scene.lidar_poses, min_range, st)
    g.save(root / "3dgs.ply")
    meta_path = root / "scene_meta.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    figures = {**figures, "min_range_m": min_range}
    meta[META_KEY] = {"settings": dataclasses.asdict(st), "figures": figures,
                      "note": "not photorealistic: false colour from LiDAR intensity and height (scene/lidar_splat.py)"}
    atomic_write_json(meta_path, meta)
    return figures
