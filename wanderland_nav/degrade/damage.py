"""Stated-rate damage to a point cloud before its collision mesh is extracted: holes and lost fragments.

Both work on horizontal (nav-frame x, y) positions, so a hole removes a whole vertical column (ground,
kerb and wall alike), the way a missing reconstruction region does. Rates are per horizontal area of
the cloud's bounding box; the returned mask says which points are kept.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from wanderland_nav.geometry import nav_from_scene_rotation


def horizontal_xy(points_scene: np.ndarray, up_axis: str) -> np.ndarray:
    """Nav-frame x, y `[N,2]` of scene points `[N,3]`."""
    return (np.asarray(points_scene, dtype=np.float64) @ nav_from_scene_rotation(up_axis).T)[:, :2]


def hole_mask(xy: np.ndarray, rng: np.random.Generator, rate_per_100m2: float, radius: float) -> tuple[np.ndarray, int]:
    """Keep-mask `[N]` after removing Poisson(rate * bbox_area / 100) discs of `radius` whose centres are
    uniform over the bounding box; also returns the number of discs."""
    keep = np.ones(len(xy), dtype=bool)
    if rate_per_100m2 <= 0 or len(xy) == 0:
        return keep, 0
    lo, hi = xy.min(0), xy.max(0)
    n = int(rng.poisson(rate_per_100m2 * float(np.prod(hi - lo)) / 100.0))
    if n == 0:
        return keep, 0
    centres = lo + rng.random((n, 2)) * (hi - lo)  # [n,2]
    hit = cKDTree(centres).query(xy, k=1, distance_upper_bound=radius)[0]  # inf where no disc is near
    return ~np.isfinite(hit), n


def fragment_mask(xy: np.ndarray, rng: np.random.Generator, rate: float, tile: float) -> tuple[np.ndarray, int]:
    """Keep-mask `[N]` after dropping each `tile` x `tile` m tile with probability `rate`; also the number
    of dropped tiles (that held points)."""
    keep = np.ones(len(xy), dtype=bool)
    if rate <= 0 or len(xy) == 0:
        return keep, 0
    ij = np.floor((xy - xy.min(0)) / tile).astype(np.int64)  # [N,2] tile index
    tiles, inverse = np.unique(ij, axis=0, return_inverse=True)
    dropped = rng.random(len(tiles)) < rate  # one draw per occupied tile, in sorted tile order
    return ~dropped[inverse.reshape(-1)], int(dropped.sum())
