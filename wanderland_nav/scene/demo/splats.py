"""Surface-aligned flat Gaussians coloured from the procedural textures (the demo `3dgs.ply`).

Like a converged 3DGS reconstruction, Gaussians exist only where the capture saw something:
on triangles hit by a camera pixel or a LiDAR beam, and within `max_range` of the trajectory.
Centres lie on a jittered square lattice of pitch `spacing` in each face's plane; the lattice
axes are world-aligned (x on horizontal faces, the horizontal direction on walls) so the two
triangles of a quad share one lattice and no seam shows. Each Gaussian is flat (tiny scale
along the normal), has in-plane sigma = `sigma_factor * spacing` so neighbours blend into a
continuous surface, and its colour is the shaded texture averaged over its own footprint.
Returned in the nav frame; the caller rotates them into the scene frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import textures
from .layout import Layout

SH_C0 = 0.28209479177387814


@dataclass
class SplatSet:
    """N flat Gaussians, nav frame, INRIA parameterisation except rotation kept as a matrix."""

    means: np.ndarray  # [N, 3]
    rotations: np.ndarray  # [N, 3, 3] columns: in-plane tangent 1, tangent 2, normal
    log_scales: np.ndarray  # [N, 3]
    opacity_logits: np.ndarray  # [N]
    sh_dc: np.ndarray  # [N, 3] = (rgb - 0.5) / SH_C0
    rgb: np.ndarray  # [N, 3] float in [0, 1]


def _tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-aligned in-plane axes `[F, 3]` x2: e1 = x projected on horizontal faces, else up x n."""
    up = np.array([0.0, 0.0, 1.0])
    horiz = np.abs(normals[:, 2]) > 0.7
    e1 = np.where(horiz[:, None], np.array([1.0, 0.0, 0.0]), np.cross(up, normals))
    e1 = e1 - np.einsum("fi,fi->f", e1, normals)[:, None] * normals
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normals, e1)
    return e1, e2


def sample_surface(layout: Layout, tri_ids: np.ndarray, spacing: float, seed: int):
    """Jittered-lattice points on the triangles `tri_ids`. Returns `(points [N, 3], tri [N])`."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 9090]))
    V = layout.vertices[layout.faces[tri_ids]]  # [F, 3, 3]
    nrm = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    e1, e2 = _tangent_frames(nrm)
    a = np.einsum("fki,fi->fk", V, e1)  # [F, 3] in-plane coordinates of the corners
    b = np.einsum("fki,fi->fk", V, e2)
    i0, i1 = np.floor(a.min(1) / spacing), np.ceil(a.max(1) / spacing)
    j0, j1 = np.floor(b.min(1) / spacing), np.ceil(b.max(1) / spacing)
    nx, ny = (i1 - i0 + 1).astype(np.int64), (j1 - j0 + 1).astype(np.int64)
    cnt = nx * ny
    f = np.repeat(np.arange(len(tri_ids)), cnt)  # candidate -> local face
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    ca = (i0[f] + local % nx[f] + rng.uniform(-0.3, 0.3, len(f))) * spacing
    cb = (j0[f] + local // nx[f] + rng.uniform(-0.3, 0.3, len(f))) * spacing
    # barycentric inside test in the face's 2D frame
    ax, ay = a[f, 0], b[f, 0]
    v0x, v0y = a[f, 1] - ax, b[f, 1] - ay
    v1x, v1y = a[f, 2] - ax, b[f, 2] - ay
    px, py = ca - ax, cb - ay
    den = v0x * v1y - v1x * v0y
    s = (px * v1y - v1x * py) / den
    t = (v0x * py - px * v0y) / den
    inside = (s >= 0) & (t >= 0) & (s + t <= 1)
    f, s, t = f[inside], s[inside], t[inside]
    Vf = V[f]
    pts = Vf[:, 0] + s[:, None] * (Vf[:, 1] - Vf[:, 0]) + t[:, None] * (Vf[:, 2] - Vf[:, 0])
    return pts, tri_ids[f], np.stack([e1[f], e2[f], nrm[f]], -1)


def make_splats(layout: Layout, seen_tris: np.ndarray, trajectory: np.ndarray, spacing: float, max_range: float,
                seed: int, sigma_factor: float = 0.55, thickness: float = 0.002, opacity: float = 0.98) -> SplatSet:
    """Flat Gaussians on the seen surfaces within `max_range` of the `trajectory [P, 3]` (nav frame)."""
    pts, tri, rot = sample_surface(layout, np.unique(seen_tris), spacing, seed)
    d, _ = cKDTree(trajectory).query(pts, k=1)
    keep = d <= max_range
    pts, tri, rot = pts[keep], tri[keep], rot[keep]
    n = rot[:, :, 2]
    rgb = textures.shade(layout.face_material[tri], pts, n, np.full(len(pts), spacing), layout.is_indoor(pts), seed,
                         layout.car_color)
    sig = sigma_factor * spacing
    log_scales = np.tile(np.log([sig, sig, thickness]), (len(pts), 1))
    logit = np.full(len(pts), np.log(opacity / (1 - opacity)))
    return SplatSet(pts, rot, log_scales, logit, (rgb - 0.5) / SH_C0, rgb)
