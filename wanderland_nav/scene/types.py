"""The in-memory `Scene` and `Camera` every other part of the framework consumes.

A Scene keeps its **native frame** (COLMAP -y up for v1, +z up for v2, whatever `scene_meta.json`
says): nothing is rotated on load, so the points, poses, Gaussians and meshes on disk stay
mutually consistent. `Scene.nav_from_scene` gives the rotation to the gravity-aligned nav frame
(z up) that the planners and the env use; `Scene.up_axis_source` says where the up axis came
from (argument, scene_meta.json or the layout's documented default) so it is never a silent guess.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import nav_from_scene_rotation, parse_up_axis


class SceneFormatError(WanderlandInputError):
    """A scene folder is missing something it needs or holds inconsistent data (names file + field)."""


@dataclass
class Camera:
    """One posed image. `world_from_cam [4,4]` float64 is in the scene frame with OpenCV camera axes
    (x right, y down, z forward); `K [3,3]` pixels; `distortion [4]` is k1..k4 for "fisheye"
    (OpenCV fisheye model) and zeros for "pinhole" (undistorted images)."""

    name: str
    world_from_cam: np.ndarray
    K: np.ndarray
    width: int
    height: int
    camera_model: str = "pinhole"  # "pinhole" | "fisheye"
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(4))
    image_path: Path | None = None
    mask_path: Path | None = None
    depth_path: Path | None = None
    side: str | None = None  # "left" | "right" | None
    split: str = "train"  # "train" | "val"

    @property
    def center(self) -> np.ndarray:
        """Camera centre `[3]` in the scene frame."""
        return self.world_from_cam[:3, 3]

    @property
    def cam_from_world(self) -> np.ndarray:
        """`[4,4]` inverse pose (what gsplat calls `viewmats`)."""
        R = self.world_from_cam[:3, :3]
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ self.world_from_cam[:3, 3]
        return T


@dataclass
class Scene:
    """A loaded scene folder. Points `[N,3]` float32 and camera poses are in the scene frame."""

    name: str
    root: Path
    version: str  # "v1" | "v2"
    up_axis: str
    points: np.ndarray  # [N,3] float32, scene frame, metres
    colors: np.ndarray  # [N,3] uint8
    cameras: list[Camera] = field(default_factory=list)
    gaussians_path: Path | None = None
    collision_mesh_path: Path | None = None
    navmesh_path: Path | None = None
    episodes_path: Path | None = None
    gt_mesh_path: Path | None = None
    environment: str | None = None  # "indoor" | "outdoor" | "mixed" | None
    indoor_regions: list[dict] = field(default_factory=list)  # nav-frame polygons (scene_meta.json schema)
    # beyond the contract: provenance and optional v2 data
    up_axis_source: str = "unspecified"
    mesh_path: Path | None = None  # v2 `scene.ply` reconstructed mesh
    # v2 LiDAR: world_from_sensor `[K,4,4]` of each `lidar/` scan (scene frame); None when unknown
    # (one registered cloud such as `colorized.las`, or scans declared registered without poses)
    lidar_poses: np.ndarray | None = None
    meta: dict = field(default_factory=dict)  # scene_meta.json content (generator info etc.)
    # where generated files (collision mesh, navmesh, episodes, goal views) go: the scene folder, or, when
    # that is read-only, a cache folder (`scene.products.products_dir`); None: the scene folder
    products_root: Path | None = None

    def __post_init__(self) -> None:
        self.up_axis = parse_up_axis(self.up_axis, source=f"scene {self.name!r} up_axis")
        self.points = np.asarray(self.points, dtype=np.float32).reshape(-1, 3)
        self.colors = np.asarray(self.colors, dtype=np.uint8).reshape(-1, 3)
        if self.colors.shape[0] != self.points.shape[0]:
            raise SceneFormatError(f"scene {self.name!r}: {self.points.shape[0]} points but "
                                   f"{self.colors.shape[0]} colours")

    @property
    def products(self) -> Path:
        """The folder generated files are written to (and looked up in first)."""
        return Path(self.products_root) if self.products_root is not None else Path(self.root)

    @property
    def nav_from_scene(self) -> np.ndarray:
        """`[3,3]` float64 rotation scene frame -> nav frame (z up)."""
        return nav_from_scene_rotation(self.up_axis)

    def camera_centers(self, split: str | None = None) -> np.ndarray:
        """Camera centres `[M,3]` float64 in the scene frame (optionally one split only)."""
        cams = [c for c in self.cameras if split is None or c.split == split]
        if not cams:
            return np.zeros((0, 3))
        return np.stack([c.world_from_cam[:3, 3] for c in cams]).astype(np.float64)

    def capture_positions(self) -> np.ndarray:
        """Scene-frame positions `[M,3]` of the capture trajectory: camera centres, else the LiDAR
        sensor positions (v2 `lidar/poses.txt`, or the origin of a single unposed scan), else `[0,3]`."""
        if self.cameras:
            return self.camera_centers()
        if self.lidar_poses is not None:
            return np.asarray(self.lidar_poses, dtype=np.float64)[:, :3, 3]
        return np.zeros((0, 3))

    def world_from_cams(self, split: str | None = None) -> np.ndarray:
        """All poses stacked `[M,4,4]` float64 (scene frame, OpenCV camera axes)."""
        cams = [c for c in self.cameras if split is None or c.split == split]
        return np.stack([c.world_from_cam for c in cams]) if cams else np.zeros((0, 4, 4))

    def is_indoor(self, points_scene) -> np.ndarray:
        """`bool[...]` for scene-frame points `[..., 3]`: inside any indoor region (nav-frame
        polygon in x,y and z_min <= z <= z_max). Scenes tagged "indoor" with no regions are all indoor."""
        p = np.asarray(points_scene, dtype=np.float64)
        shape = p.shape[:-1]
        if self.environment == "indoor" and not self.indoor_regions:
            return np.ones(shape, dtype=bool)
        q = p.reshape(-1, 3) @ self.nav_from_scene.T  # [P,3] nav frame
        inside = np.zeros(q.shape[0], dtype=bool)
        for reg in self.indoor_regions:  # few regions; points are batched
            poly = np.asarray(reg["polygon_xy"], dtype=np.float64)
            zin = (q[:, 2] >= float(reg.get("z_min", -np.inf))) & (q[:, 2] <= float(reg.get("z_max", np.inf)))
            inside |= zin & points_in_polygon(q[:, :2], poly)
        return inside.reshape(shape)

    def summary(self) -> dict:
        """Small dict for logs / CLI output."""
        n_val = sum(c.split == "val" for c in self.cameras)
        return {"name": self.name, "version": self.version, "up_axis": self.up_axis,
                "up_axis_source": self.up_axis_source, "points": int(self.points.shape[0]),
                "cameras": len(self.cameras), "cameras_val": int(n_val), "environment": self.environment}


def points_in_polygon(xy: np.ndarray, poly: np.ndarray, *, chunk: int = 1 << 20) -> np.ndarray:
    """Even-odd rule, batched over points: `xy [P,2]`, `poly [V,2]` -> `bool [P]`.

    Works on chunks of points so memory stays at O(chunk * V) for million-point clouds."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    a = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    dy = b[:, 1] - a[:, 1]
    slope = (b[:, 0] - a[:, 0]) / np.where(dy == 0, 1.0, dy)  # [V] dx/dy of each edge
    out = np.empty(xy.shape[0], dtype=bool)
    step = max(1, chunk // max(1, a.shape[0]))
    for s in range(0, xy.shape[0], step):
        x, y = xy[s:s + step, None, 0], xy[s:s + step, None, 1]  # [p,1]
        crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)  # [p,V]
        x_at = a[None, :, 0] + (y - a[None, :, 1]) * slope[None, :]
        out[s:s + step] = (crosses & (x < x_at)).sum(-1) % 2 == 1
    return out
