"""The pose error of a degraded build as one field: every capture camera gets a rigid correction,
and everything reconstructed from the capture (points, Gaussians, other poses) inherits the
correction of its nearest camera, then the whole world is scaled.

For camera i with centre c_i (scene frame) and drift (R_i [3,3], t_i [3]) a scene point p becomes

    p' = s * (R_i (p - c_i) + c_i + t_i)          i = nearest capture camera to p

so a camera's own centre moves to s (c_i + t_i) and its orientation becomes R_i R_cam; the drift
rotates geometry about the camera that saw it (as an SfM pose error does), not about a far origin.
With no drift and s = 1 the field is exactly the identity. Rotations by R_i keep lengths, so any two
points with the same nearest camera keep their distance times s exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from wanderland_nav.atomic import atomic_path
from wanderland_nav.geometry import up_vector

from .spec import DegradeSpec


@dataclass
class PoseCorrection:
    """`centers [M,3]`, `R [M,3,3]`, `t [M,3]` (scene frame, metres) and the global `scale`."""

    centers: np.ndarray
    R: np.ndarray
    t: np.ndarray
    scale: float

    def __post_init__(self) -> None:
        self._tree = cKDTree(self.centers) if len(self.centers) else None
        # the identity field must return its input bit for bit (R (p - c) + c rounds otherwise)
        self.is_identity = self.scale == 1.0 and not np.any(self.t) and bool(np.all(self.R == np.eye(3)))

    def nearest(self, points: np.ndarray) -> np.ndarray:
        """Index `[N]` of the nearest capture camera of each scene point `[N,3]`."""
        if self._tree is None:
            return np.zeros(len(points), dtype=np.int64)
        return self._tree.query(np.asarray(points, dtype=np.float64), k=1)[1].astype(np.int64)

    def apply_points(self, points: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """Scene points `[N,3]` -> degraded scene frame `[N,3]` (float64)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.is_identity:
            return p.copy()
        if self._tree is None:
            return self.scale * p
        i = self.nearest(p) if idx is None else idx
        c = self.centers[i]
        return self.scale * (np.einsum("nij,nj->ni", self.R[i], p - c) + c + self.t[i])

    def apply_rotations(self, points: np.ndarray, R_world: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """Orientations `[N,3,3]` (world_from_local) of things at `points [N,3]` -> `R_i @ R_world`."""
        if self._tree is None:
            return np.asarray(R_world, dtype=np.float64)
        i = self.nearest(points) if idx is None else idx
        return np.einsum("nij,njk->nik", self.R[i], np.asarray(R_world, dtype=np.float64))

    def apply_poses(self, world_from_cam: np.ndarray) -> np.ndarray:
        """Camera poses `[N,4,4]` (world_from_cam, any camera-axis convention) -> degraded poses."""
        T = np.asarray(world_from_cam, dtype=np.float64).reshape(-1, 4, 4)
        c = T[:, :3, 3]
        idx = self.nearest(c)
        out = T.copy()
        out[:, :3, :3] = self.apply_rotations(c, T[:, :3, :3], idx)
        out[:, :3, 3] = self.apply_points(c, idx)
        return out

    def save(self, path: Path) -> None:
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez(f, centers=self.centers, R=self.R, t=self.t, scale=np.float64(self.scale))

    @classmethod
    def load(cls, path: Path) -> "PoseCorrection":
        try:
            with np.load(path) as z:
                return cls(z["centers"], z["R"], z["t"], float(z["scale"]))
        except (OSError, KeyError, ValueError) as e:
            raise ValueError(f"{path}: not a pose-correction file written by wanderland_nav.degrade ({e})") from None


def pose_correction(centers: np.ndarray, up_axis: str, spec: DegradeSpec, rng: np.random.Generator) -> PoseCorrection:
    """Draw the correction field for capture centres `[M,3]` taken in capture order.

    Drift is a random walk in distance travelled: after L metres its per-axis translation std is
    `drift_m_at_100m * sqrt(L / 100)` and its heading std `drift_deg_at_100m * sqrt(L / 100)` (about
    the scene's up axis). White per-frame noise is added on top. The draws are made even when a rate is
    zero, so changing one rate does not reshuffle the others.
    """
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    M = len(c)
    step = np.r_[0.0, np.linalg.norm(np.diff(c, axis=0), axis=1)]  # [M] metres since the previous frame
    walk_t = rng.standard_normal((M, 3)) * np.sqrt(step / 100.0)[:, None]
    walk_yaw = rng.standard_normal(M) * np.sqrt(step / 100.0)
    noise_t = rng.standard_normal((M, 3))
    noise_axis = rng.standard_normal((M, 3))
    noise_ang = rng.standard_normal(M)
    t = spec.drift_m_at_100m * np.cumsum(walk_t, axis=0) + spec.pose_noise_m * noise_t
    yaw = np.deg2rad(spec.drift_deg_at_100m) * np.cumsum(walk_yaw)
    up = up_vector(up_axis).astype(np.float64)
    R = Rotation.from_rotvec(yaw[:, None] * up[None, :]).as_matrix()
    axis = noise_axis / np.maximum(np.linalg.norm(noise_axis, axis=1, keepdims=True), 1e-12)
    R = Rotation.from_rotvec(axis * (np.deg2rad(spec.pose_noise_deg) * noise_ang)[:, None]).as_matrix() @ R
    if not spec.drift_deg_at_100m and not spec.pose_noise_deg:
        R = np.broadcast_to(np.eye(3), (M, 3, 3)).copy()  # exactly the identity, not 1 - 1e-16
    return PoseCorrection(c, R, t, float(spec.scale))
