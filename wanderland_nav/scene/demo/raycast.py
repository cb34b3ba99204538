"""Batched first-hit ray casting against the ground-truth triangle mesh.

This is the demo scene's *independent* image path: pixels and LiDAR returns come from exact
ray/triangle hits, never from the splat renderer, so comparing a splat render with these
images measures the splats. Two backends give the same hits:

* "embree" (when `embreex` is installed): Embree through trimesh finds the first triangle,
  ~3 M rays/s per core;
* "numpy": a two-level brute force without extra dependencies: triangles are grouped into
  clusters of `CLUSTER` (sorted by size class, then Morton order of their centroids, so big
  ground quads share clusters and small furniture triangles cluster in space); every ray is slab-
  tested against each cluster's box (a loop over ~100 clusters, each step batched over all rays)
  and only rays that reach a box are Moller-Trumbore-tested against its triangles. About 250x
  slower than Embree (~3 k rays/s): a correctness reference and a last resort, not a way to
  build the default preset (install `embreex`).

Either way the hit distance is recomputed in float64 from the hit triangle's plane, so depths
do not carry float32 rounding and the two backends agree to ~1e-9 m on the same triangle.
"""

from __future__ import annotations

import logging

import numpy as np
import trimesh

log = logging.getLogger(__name__)
_CHUNK = 1 << 20
CLUSTER = 32


class RayCaster:
    """First hits of rays against a fixed triangle soup (any frame; metres)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, backend: str = "auto"):
        self.vertices = np.asarray(vertices, np.float64)
        self.faces = np.asarray(faces, np.int64)
        tri = self.vertices[self.faces]  # [F, 3, 3]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.normals = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)  # [F, 3] outward unit normals
        self._offset = np.einsum("fi,fi->f", self.normals, tri[:, 0])  # plane: n . x = offset
        if backend not in ("auto", "embree", "numpy"):
            raise ValueError(f"RayCaster: backend must be 'auto', 'embree' or 'numpy', got {backend!r}")
        self._embree = None
        if backend in ("auto", "embree"):
            try:
                from trimesh.ray.ray_pyembree import RayMeshIntersector

                mesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
                self._embree = RayMeshIntersector(mesh, scale_to_box=False)
            except ImportError:
                if backend == "embree":
                    raise ImportError("RayCaster(backend='embree') needs the 'embreex' package") from None
        self.backend = "embree" if self._embree is not None else "numpy"
        if self._embree is None:
            if backend == "auto":
                log.warning("embreex is not installed: ray casting falls back to the slow numpy backend "
                            "(pip install embreex)")
            self._build_clusters(tri)

    # ------------------------------------------------------------------ numpy backend

    def _build_clusters(self, tri: np.ndarray) -> None:
        lo, hi = tri.min(1), tri.max(1)
        size = np.floor(np.log2(np.linalg.norm(hi - lo, axis=1) + 1e-9)).astype(np.int64)
        c = 0.5 * (lo + hi)
        q = ((c - c.min(0)) / max(np.ptp(c, axis=0).max(), 1e-9) * 1023).astype(np.uint64)  # 10 bits per axis
        code = np.zeros(len(q), np.uint64)
        for bit in range(10):  # interleave x, y, z bits (Morton)
            for ax in range(3):
                code |= ((q[:, ax] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + ax)
        order = np.lexsort((code, -size))  # big triangles first, then spatially coherent
        self._members = [order[a:a + CLUSTER] for a in range(0, len(order), CLUSTER)]
        self._box_lo = np.stack([lo[m].min(0) for m in self._members])
        self._box_hi = np.stack([hi[m].max(0) for m in self._members])
        self._v0 = tri[:, 0]
        self._e1 = tri[:, 1] - tri[:, 0]
        self._e2 = tri[:, 2] - tri[:, 0]

    def _first_numpy(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        n = len(o)
        best_t = np.full(n, np.inf)
        best = np.full(n, -1, np.int64)
        inv = 1.0 / np.where(np.abs(d) < 1e-12, 1e-12, d)
        for g, tris in enumerate(self._members):
            t1 = (self._box_lo[g] - o) * inv
            t2 = (self._box_hi[g] - o) * inv
            tmin = np.minimum(t1, t2).max(1)
            tmax = np.maximum(t1, t2).min(1)
            cand = np.flatnonzero((tmax >= np.maximum(tmin, 0.0)) & (tmin < best_t))
            if cand.size == 0:
                continue
            oc, dc = o[cand][:, None], d[cand][:, None]  # [c, 1, 3]
            e1, e2, v0 = self._e1[tris][None], self._e2[tris][None], self._v0[tris][None]  # [1, k, 3]
            p = np.cross(dc, e2)  # [c, k, 3]
            det = (e1 * p).sum(-1)
            ok = np.abs(det) > 1e-14
            inv_det = 1.0 / np.where(ok, det, 1.0)
            s = oc - v0
            u = (s * p).sum(-1) * inv_det
            qv = np.cross(s, e1)
            v = (dc * qv).sum(-1) * inv_det
            t = (e2 * qv).sum(-1) * inv_det
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
            t = np.where(hit, t, np.inf)
            j = t.argmin(1)
            tm = t[np.arange(len(cand)), j]
            upd = tm < best_t[cand]
            best_t[cand[upd]] = tm[upd]
            best[cand[upd]] = tris[j[upd]]
        return best

    # ------------------------------------------------------------------ public

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`origins [N, 3]`, unit `directions [N, 3]` -> `(t [N] float64, inf on a miss; tri [N] int64, -1)`."""
        origins = np.asarray(origins, np.float64)
        directions = np.asarray(directions, np.float64)
        n = origins.shape[0]
        tri = np.empty(n, np.int64)
        step = _CHUNK if self._embree is not None else _CHUNK // 8
        for a in range(0, n, step):
            o, d = origins[a:a + step], directions[a:a + step]
            tri[a:a + step] = self._embree.intersects_first(o, d) if self._embree is not None else self._first_numpy(o, d)
        t = np.full(n, np.inf)
        hit = np.flatnonzero(tri >= 0)
        nh = self.normals[tri[hit]]
        denom = np.einsum("ni,ni->n", nh, directions[hit])
        th = (self._offset[tri[hit]] - np.einsum("ni,ni->n", nh, origins[hit])) / np.where(np.abs(denom) < 1e-12, 1e-12, denom)
        t[hit] = np.maximum(th, 0.0)
        return t, tri
