"""Batched first-hit ray casting against the ground-truth triangle mesh.

This is the demo scene's *independent* image path: pixels and LiDAR returns come from exact
ray/triangle hits, never from the splat renderer, so comparing a splat render with these
images measures the splats. Embree (via `embreex`, through trimesh) finds the first triangle
(~3 M rays/s on one core); the hit distance is then recomputed in float64 from the triangle's
plane, so depths do not carry Embree's float32 rounding. Without `embreex`, trimesh's pure
numpy intersector is used (same results, much slower: fine for the tiny preset only).
"""

from __future__ import annotations

import numpy as np
import trimesh

_CHUNK = 1 << 20


class RayCaster:
    """First hits of rays against a fixed triangle soup (any frame; metres)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), process=False)
        try:
            from trimesh.ray.ray_pyembree import RayMeshIntersector

            self._isect = RayMeshIntersector(mesh, scale_to_box=False)
            self.backend = "embree"
        except ImportError:  # pragma: no cover - exercised only where embreex is missing
            from trimesh.ray.ray_triangle import RayMeshIntersector

            self._isect = RayMeshIntersector(mesh)
            self.backend = "numpy"
        tri = mesh.vertices[mesh.faces]  # [F, 3, 3]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.normals = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)  # [F, 3] outward unit normals
        self._offset = np.einsum("fi,fi->f", self.normals, tri[:, 0])  # plane: n . x = offset

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`origins [N, 3]`, unit `directions [N, 3]` -> `(t [N] float64, inf on a miss; tri [N] int64, -1)`."""
        origins = np.asarray(origins, np.float64)
        directions = np.asarray(directions, np.float64)
        n = origins.shape[0]
        tri = np.empty(n, np.int64)
        for a in range(0, n, _CHUNK):
            tri[a:a + _CHUNK] = self._isect.intersects_first(origins[a:a + _CHUNK], directions[a:a + _CHUNK])
        t = np.full(n, np.inf)
        hit = np.flatnonzero(tri >= 0)
        nh = self.normals[tri[hit]]
        denom = np.einsum("ni,ni->n", nh, directions[hit])
        th = (self._offset[tri[hit]] - np.einsum("ni,ni->n", nh, origins[hit])) / np.where(np.abs(denom) < 1e-12, 1e-12, denom)
        t[hit] = np.maximum(th, 0.0)
        return t, tri
