"""`PoseSet`: the one in-memory form every reconstruction input is read into.

Why one form: COLMAP stores world-to-camera, transforms.json camera-to-world in OpenGL axes, TUM
camera(or IMU)-to-world; converting all of them once at the file boundary means alignment and
metrics see a single convention and can never mix them up:

* `world_from_cam [N, 4, 4]` float64, OpenCV camera axes (x right, y down, z forward) where the
  source defines a camera (TUM files carry whatever body frame the tool wrote: the metrics that use
  orientations compare like with like, so only the translation part needs a common meaning);
* cameras are keyed by `names` (COLMAP, scenes, transforms.json) or `stamps` (TUM, seconds).

Validation happens here, once, for every reader: NaN / non-rigid poses and duplicate keys raise
`ReconInputError` naming the file and the entry.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from wanderland_nav.geometry import validate_rigid


class ReconInputError(ValueError):
    """A prediction / ground-truth input is missing, malformed or degenerate (names file and field)."""


@dataclass(frozen=True)
class PoseSet:
    """Posed cameras from one file or folder: `world_from_cam [N,4,4]` plus names or stamps."""

    world_from_cam: np.ndarray  # [N, 4, 4] float64, camera-to-world, OpenCV axes
    source: str  # file or folder it came from, for messages
    kind: str  # "colmap" | "scene" | "transforms" | "tum"
    names: tuple[str, ...] | None = None  # [N] image names (matched by name)
    stamps: np.ndarray | None = None  # [N] float64 seconds (matched by nearest stamp)
    duplicates_dropped: int = 0  # repeated stamps the reader left out (TUM: first occurrence kept)
    up_axis: str | None = None  # the world's up axis when the source records one (scene folders)

    def __post_init__(self) -> None:
        T = np.asarray(self.world_from_cam, dtype=np.float64).reshape(-1, 4, 4)
        object.__setattr__(self, "world_from_cam", T)
        keys = self.names if self.names is not None else self.stamps
        if (self.names is None) == (self.stamps is None):
            raise ValueError(f"{self.source}: a PoseSet needs exactly one of names / stamps")
        if len(keys) != T.shape[0]:
            raise ReconInputError(f"{self.source}: {T.shape[0]} poses but {len(keys)} names/stamps")
        if T.shape[0]:
            bad = np.flatnonzero(~np.isfinite(T.reshape(-1, 16)).all(-1))
            if bad.size:
                raise ReconInputError(f"{self.source}: non-finite (NaN/inf) pose for {self.label(int(bad[0]))} "
                                      f"({bad.size} in all)")
            try:
                validate_rigid(T, what=f"{self.source}: pose")
            except ValueError as e:
                raise ReconInputError(str(e)) from None
        self._check_unique()

    def _check_unique(self) -> None:
        if self.names is not None:
            seen: set[str] = set()
            for n in self.names:
                if n in seen:
                    raise ReconInputError(f"{self.source}: image name {n!r} appears twice (field name)")
                seen.add(n)
            return
        s = np.asarray(self.stamps, dtype=np.float64)
        if not np.isfinite(s).all():
            raise ReconInputError(f"{self.source}: non-finite timestamp at row {int(np.argmin(np.isfinite(s)))}")
        order = np.sort(s)
        dup = np.flatnonzero(np.diff(order) == 0)
        if dup.size:
            raise ReconInputError(f"{self.source}: timestamp {order[dup[0]]:.6f} appears twice (field timestamp)")

    def __len__(self) -> int:
        return int(self.world_from_cam.shape[0])

    def label(self, i: int) -> str:
        return f"image {self.names[i]!r}" if self.names is not None else f"stamp {float(self.stamps[i]):.6f}"

    @property
    def centers(self) -> np.ndarray:
        """Camera centres `[N, 3]` (world frame)."""
        return self.world_from_cam[:, :3, 3]

    def subset(self, idx: np.ndarray) -> "PoseSet":
        idx = np.asarray(idx, dtype=np.int64)
        names = None if self.names is None else tuple(self.names[i] for i in idx)
        stamps = None if self.stamps is None else np.asarray(self.stamps)[idx]
        return PoseSet(self.world_from_cam[idx], self.source, self.kind, names, stamps, self.duplicates_dropped,
                       self.up_axis)


def from_cam_from_world(cam_from_world: np.ndarray) -> np.ndarray:
    """World-to-camera `[N,4,4]` (COLMAP, gsplat viewmats) -> camera-to-world, with R^T (rigid inverse)."""
    E = np.asarray(cam_from_world, dtype=np.float64).reshape(-1, 4, 4)
    R = np.swapaxes(E[:, :3, :3], -1, -2)
    T = np.tile(np.eye(4), (E.shape[0], 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = -(R @ E[:, :3, 3:4])[..., 0]
    return T
