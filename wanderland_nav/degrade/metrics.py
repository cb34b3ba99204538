"""Geometry metrics of a degraded environment against the grounded one.

Surfaces are compared by exact point-to-surface distances from area-uniform samples of one surface to
the other's triangles (not sample-to-sample: at a 5 cm threshold that would need ~10^7 samples), in the
grounded scene frame with no alignment: a policy trained in the degraded world sees it as it is, so a
scale error counts in full.

* accuracy@tau: share of degraded-surface samples within tau of the reference surface (precision);
* completeness@tau: share of reference samples within tau of the degraded surface (recall);
* chamfer: mean of the two mean nearest-neighbour distances (metres);
* walkable area (m^2) and island count of both navmeshes, and their difference;
* feasible episodes: grounded expert episodes whose start and goal, mapped into the degraded world by
  its pose-error field, snap onto ONE island of the degraded navmesh.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np
import trimesh
from scipy.spatial import cKDTree

THRESHOLDS = (0.05, 0.10, 0.20)


def sample_surface(mesh, n: int, seed: int) -> np.ndarray:
    """`[n,3]` points uniform by area on a trimesh (seeded; same seed, same points)."""
    if len(mesh.faces) == 0:
        return np.zeros((0, 3))
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


def _segment_distance(p, a, b):
    """Distance `[...]` from points `p [...,3]` to segments a-b `[...,3]`."""
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-24), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _triangle_distance(p, tri):
    """Distance `[...]` from `p [...,3]` to triangles `tri [...,3,3]`: the plane distance where the
    projection falls inside, else the nearest edge."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    n = np.cross(b - a, c - a)
    nn = np.maximum(np.linalg.norm(n, axis=-1), 1e-24)
    h = ((p - a) * n).sum(-1) / nn  # signed plane distance
    q = p - (h / nn)[..., None] * n  # projection on the plane
    inside = np.ones(h.shape, dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):  # same side of all three edges as the normal
        inside &= (np.cross(v - u, q - u) * n).sum(-1) >= 0
    edge = np.minimum(np.minimum(_segment_distance(p, a, b), _segment_distance(p, b, c)), _segment_distance(p, c, a))
    return np.where(inside, np.abs(h), edge)


class SurfaceDistance:
    """Point-to-surface distance to a triangle mesh.

    The mesh is subdivided until no edge exceeds `max_edge`; a query tests the `k` triangles with the
    nearest centroids. That is exact whenever the nearest triangle is among them, which with small
    triangles holds for all but a negligible share of points (the test checks it against trimesh's
    exhaustive `closest_point`).
    """

    def __init__(self, mesh, *, max_edge: float = 0.3, k: int = 12):
        v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
        if len(f) == 0:
            raise ValueError("SurfaceDistance: the mesh has no faces")
        v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge=max_edge)
        self.tri = v[f]  # [F,3,3]
        self.k = min(k, len(f))
        self._tree = cKDTree(self.tri.mean(1))

    def __call__(self, points: np.ndarray, chunk: int = 65536) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.empty(len(p))
        for s in range(0, len(p), chunk):  # memory bound: chunk * k triangles at a time
            q = p[s:s + chunk]
            idx = self._tree.query(q, k=self.k)[1].reshape(len(q), -1)  # [n,k]
            out[s:s + chunk] = _triangle_distance(q[:, None, :], self.tri[idx]).min(1)
        return out


_BUILT: OrderedDict = OrderedDict()  # mesh content + settings -> SurfaceDistance, the last few built
_KEEP = 4  # a report's two surfaces and the grounded pair every world of a study is measured against


def surface_distance(mesh, *, max_edge: float = 0.3, k: int = 12) -> SurfaceDistance:
    """`SurfaceDistance(mesh)`, reused while a mesh of the same vertices and faces was one of the last few asked
    for: a study measures every degraded world against the same grounded meshes, and each surface twice."""
    v, f = np.ascontiguousarray(mesh.vertices, np.float64), np.ascontiguousarray(mesh.faces, np.int64)
    h = hashlib.blake2b(v.tobytes(), digest_size=16)
    h.update(f.tobytes())
    key = (h.hexdigest(), len(v), len(f), float(max_edge), int(k))
    if key in _BUILT:
        _BUILT.move_to_end(key)
        return _BUILT[key]
    _BUILT[key] = built = SurfaceDistance(mesh, max_edge=max_edge, k=k)
    while len(_BUILT) > _KEEP:
        _BUILT.popitem(last=False)
    return built


def surface_metrics(pred_mesh, ref_mesh, *, samples: int = 100_000, seed: int = 0, thresholds=THRESHOLDS,
                    observed: np.ndarray | None = None, observed_radius: float = 0.3) -> dict[str, float]:
    """Accuracy / completeness at each threshold and the Chamfer distance between two meshes.

    `observed [P,3]`: points the capture actually saw (the grounded LiDAR cloud). When given, reference
    samples farther than `observed_radius` from all of them are left out: a ground-truth mesh of the
    whole block also holds roofs and back yards no capture could reconstruct, and completeness is
    measured over what was seen (the observation mask of the DTU and Tanks-and-Temples protocols).
    """
    pred_pts, ref_pts = sample_surface(pred_mesh, samples, seed), sample_surface(ref_mesh, samples, seed + 1)
    if observed is not None and len(ref_pts):
        ref_pts = ref_pts[cKDTree(np.asarray(observed, np.float64)).query(ref_pts, k=1)[0] <= observed_radius]
    if len(pred_pts) == 0 or len(ref_pts) == 0:
        raise ValueError(f"surface_metrics: empty mesh (pred {len(pred_mesh.faces)}, reference "
                         f"{len(ref_mesh.faces)} faces)")
    d_pred = surface_distance(ref_mesh)(pred_pts)  # degraded -> reference surface
    d_ref = surface_distance(pred_mesh)(ref_pts)  # reference -> degraded surface
    out = {"chamfer_m": 0.5 * (float(d_pred.mean()) + float(d_ref.mean()))}
    for t in thresholds:
        cm = int(round(t * 100))
        out[f"accuracy@{cm}cm"] = float((d_pred <= t).mean())
        out[f"completeness@{cm}cm"] = float((d_ref <= t).mean())
    return out


def navmesh_metrics(pred_nm, ref_nm) -> dict[str, float]:
    """Walkable area and islands of both navmeshes."""
    a, b = float(pred_nm.area), float(ref_nm.area)
    return {"walkable_m2": a, "walkable_m2_grounded": b, "walkable_diff_m2": a - b,
            "walkable_ratio": a / b if b > 0 else float("nan"),
            "islands": len(pred_nm.islands), "islands_grounded": len(ref_nm.islands)}


def feasible_episodes(starts: np.ndarray, goals: np.ndarray, pred_nm, correction) -> np.ndarray:
    """`bool [E]`: grounded episode (start, goal) `[E,3]` scene-frame positions, mapped by `correction`
    (a `PoseCorrection`), snap onto the same island of `pred_nm`."""
    if len(pred_nm.tris) == 0:  # nothing walkable: no episode survives
        return np.zeros(len(starts), dtype=bool)
    s = pred_nm.island_of(correction.apply_points(starts))
    g = pred_nm.island_of(correction.apply_points(goals))
    return (s >= 0) & (s == g)
