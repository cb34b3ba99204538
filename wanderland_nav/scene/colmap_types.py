"""COLMAP's data: camera models, cameras, images, the 3D points, a whole model, and quaternion <-> matrix.

Its own module so that the binary format (`scene.colmap`) and the text format (`scene.colmap_text`) both
import it and neither imports the other's types. Conventions and the error contract are documented in
`scene.colmap`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import torch

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import quat_to_rotmat, rotmat_to_quat

log = logging.getLogger("wanderland_nav.scene.colmap")


class ColmapFormatError(WanderlandInputError):
    """A COLMAP file is missing, truncated or malformed (message names file and field)."""


@dataclass(frozen=True)
class CameraModel:
    model_id: int
    name: str
    num_params: int
    param_names: tuple[str, ...]


# Every model COLMAP defines (colmap/src/colmap/sensor/models.h), id -> layout.
_MODELS = [
    CameraModel(0, "SIMPLE_PINHOLE", 3, ("f", "cx", "cy")),
    CameraModel(1, "PINHOLE", 4, ("fx", "fy", "cx", "cy")),
    CameraModel(2, "SIMPLE_RADIAL", 4, ("f", "cx", "cy", "k")),
    CameraModel(3, "RADIAL", 5, ("f", "cx", "cy", "k1", "k2")),
    CameraModel(4, "OPENCV", 8, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")),
    CameraModel(5, "OPENCV_FISHEYE", 8, ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")),
    CameraModel(6, "FULL_OPENCV", 12, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")),
    CameraModel(7, "FOV", 5, ("fx", "fy", "cx", "cy", "omega")),
    CameraModel(8, "SIMPLE_RADIAL_FISHEYE", 4, ("f", "cx", "cy", "k")),
    CameraModel(9, "RADIAL_FISHEYE", 5, ("f", "cx", "cy", "k1", "k2")),
    CameraModel(10, "THIN_PRISM_FISHEYE", 12, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1")),
    CameraModel(11, "RAD_TAN_THIN_PRISM_FISHEYE", 16,
                ("fx", "fy", "cx", "cy", "k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1", "s2", "s3")),
]
CAMERA_MODELS: dict[int, CameraModel] = {m.model_id: m for m in _MODELS}
_WARNED_DROPPED: set[tuple[str, int]] = set()  # (model, camera id) already warned about unmodelled distortion


def _num_distortion(m: "CameraModel") -> int:
    """How many of a model's parameters are distortion terms (all after f / fx, fy, cx, cy)."""
    return m.num_params - (3 if m.param_names[0] == "f" else 4)


CAMERA_MODELS_BY_NAME: dict[str, CameraModel] = {m.name: m for m in _MODELS}
FISHEYE_MODELS = {"OPENCV_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "THIN_PRISM_FISHEYE",
                  "RAD_TAN_THIN_PRISM_FISHEYE", "FOV"}


def camera_model(key: int | str) -> CameraModel:
    """Look a model up by COLMAP id or name (case-insensitive)."""
    if isinstance(key, str):
        m = CAMERA_MODELS_BY_NAME.get(key.strip().upper())
    else:
        m = CAMERA_MODELS.get(int(key))
    if m is None:
        raise KeyError(f"unknown COLMAP camera model {key!r}; known: {sorted(CAMERA_MODELS_BY_NAME)}")
    return m


# --------------------------------------------------------------------------- data classes


@dataclass
class ColmapCamera:
    camera_id: int
    model: str  # COLMAP model name, e.g. "PINHOLE"
    width: int
    height: int
    params: np.ndarray  # [num_params] float64, in CameraModel.param_names order

    def intrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """`(K [3,3], distortion [4])` in the (pinhole|OpenCV-fisheye) convention the Scene uses.

        distortion holds k1..k4 for fisheye models and (k1, k2, p1, p2) for OPENCV; models with
        more terms keep their first four, which is what a renderer without them can honour.
        """
        m = camera_model(self.model)
        p = dict(zip(m.param_names, np.asarray(self.params, dtype=np.float64)))
        fx = p.get("fx", p.get("f"))
        fy = p.get("fy", p.get("f"))
        K = np.array([[fx, 0.0, p["cx"]], [0.0, fy, p["cy"]], [0.0, 0.0, 1.0]])
        if m.name in ("SIMPLE_RADIAL", "SIMPLE_RADIAL_FISHEYE"):
            d = [p["k"], 0.0, 0.0, 0.0]
        elif m.name in ("RADIAL", "RADIAL_FISHEYE"):
            d = [p["k1"], p["k2"], 0.0, 0.0]
        elif m.name == "OPENCV":
            d = [p["k1"], p["k2"], p["p1"], p["p2"]]
        elif m.name == "FULL_OPENCV":  # radial-tangential like OPENCV (was k1, k2, k3, k4: read as p1, p2)
            d = [p["k1"], p["k2"], p["p1"], p["p2"]]
        elif m.name in ("OPENCV_FISHEYE", "THIN_PRISM_FISHEYE"):
            d = [p["k1"], p["k2"], p["k3"], p["k4"]]
        elif m.name == "RAD_TAN_THIN_PRISM_FISHEYE":
            d = [p["k0"], p["k1"], p["k2"], p["k3"]]
        else:
            d = [0.0] * 4
        kept = {"OPENCV": ("k1", "k2", "p1", "p2"), "FULL_OPENCV": ("k1", "k2", "p1", "p2"),
                "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4"), "THIN_PRISM_FISHEYE": ("k1", "k2", "k3", "k4"),
                "RAD_TAN_THIN_PRISM_FISHEYE": ("k0", "k1", "k2", "k3"), "SIMPLE_RADIAL": ("k",),
                "SIMPLE_RADIAL_FISHEYE": ("k",), "RADIAL": ("k1", "k2"), "RADIAL_FISHEYE": ("k1", "k2")}.get(m.name, ())
        dropped = tuple(n for n in m.param_names[len(m.param_names) - _num_distortion(m):] if n not in kept and p[n] != 0)
        if dropped and (m.name, self.camera_id) not in _WARNED_DROPPED:
            _WARNED_DROPPED.add((m.name, self.camera_id))
            log.warning("COLMAP camera %d (%s): distortion terms %s are not modelled (only %s are): images of "
                        "this camera are undistorted approximately", self.camera_id, m.name, list(dropped),
                        list(kept) or "none")
        return K, np.asarray(d, dtype=np.float64)


@dataclass
class ColmapImage:
    image_id: int
    qvec: np.ndarray  # [4] float64, cam_from_world rotation, wxyz
    tvec: np.ndarray  # [3] float64, cam_from_world translation
    camera_id: int
    name: str
    xys: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # [P,2] float64 pixel coords
    point3D_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # [P] int64, -1 = none

    def cam_from_world(self) -> np.ndarray:
        """`[4,4]` float64 pose as stored by COLMAP."""
        T = np.eye(4)
        T[:3, :3] = qvec_to_rotmat(self.qvec)
        T[:3, 3] = self.tvec
        return T

    def world_from_cam(self) -> np.ndarray:
        """`[4,4]` float64 camera-to-world pose (OpenCV camera axes, world = COLMAP frame)."""
        R = qvec_to_rotmat(self.qvec)
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ np.asarray(self.tvec, dtype=np.float64)
        return T


@dataclass
class ColmapPoints3D:
    """All 3D points as arrays (struct of arrays: a scene has 1e5-1e6 of them).

    Tracks are stored CSR-style: the track of point i is
    `track_image_ids[track_offsets[i]:track_offsets[i+1]]` (and `track_point2D_idxs` likewise).
    """

    ids: np.ndarray  # [N] int64
    xyz: np.ndarray  # [N,3] float64, world (COLMAP) frame
    rgb: np.ndarray  # [N,3] uint8
    error: np.ndarray  # [N] float64 reprojection error (px)
    track_offsets: np.ndarray  # [N+1] int64
    track_image_ids: np.ndarray  # [T] int32
    track_point2D_idxs: np.ndarray  # [T] int32

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    @staticmethod
    def empty() -> "ColmapPoints3D":
        return ColmapPoints3D(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0),
                              np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32))


def qvec_to_rotmat(q) -> np.ndarray:
    """A COLMAP wxyz quaternion `[4]` (normalised; a non-finite or zero one is refused) -> rotation `[3,3]` float64,
    by `geometry.quat_to_rotmat`."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"quaternion {q.tolist()} is not finite / has zero norm")
    return quat_to_rotmat(torch.from_numpy(q)).numpy()


def rotmat_to_qvec(R) -> np.ndarray:
    """Rotation `[3,3]` -> COLMAP's unit wxyz quaternion `[4]` with w >= 0, by `geometry.rotmat_to_quat`."""
    return rotmat_to_quat(torch.as_tensor(np.asarray(R, dtype=np.float64))).numpy()


@dataclass
class ColmapModel:
    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points3D: ColmapPoints3D
