"""Top-down PNG of a scene's episodes: navmesh, capture trajectory and a sample of expert paths.

Why: a wrong up axis, a navmesh on the roof, or episodes that all start at one camera show up at
a glance in this picture, long before a policy fails to train. Everything is drawn in the nav
frame (x, y on the ground plane, seen from above), so a scene looks the same whatever its
native up axis. matplotlib is imported here only (viz/ is the only place allowed to).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from wanderland_nav.atomic import atomic_path


def navmesh_triangles_nav(navmesh, R_ns: np.ndarray) -> np.ndarray | None:
    """`[T, 3, 3]` nav-frame triangles of the navmesh if the planner exposes them, else None."""
    for name in ("triangles", "triangles_scene"):
        tri = getattr(navmesh, name, None)
        tri = tri() if callable(tri) else tri
        if tri is not None:
            tri = np.asarray(tri, dtype=np.float64)
            if tri.ndim == 3 and tri.shape[1:] == (3, 3):
                return tri @ R_ns.T
    # planners.NavMesh keeps its triangles in a local nav frame offset by bmin (xy and z separately)
    if all(hasattr(navmesh, k) for k in ("verts_xy", "verts_z", "tris", "bmin")):
        t = np.asarray(navmesh.tris)
        if t.ndim == 2 and t.shape[1] == 3:
            loc = np.concatenate([np.asarray(navmesh.verts_xy)[t], np.asarray(navmesh.verts_z)[t][..., None]], -1)
            return loc.astype(np.float64) + np.asarray(navmesh.bmin, dtype=np.float64)
    verts, faces = getattr(navmesh, "vertices", None), getattr(navmesh, "faces", None)
    if verts is not None and faces is not None:
        v = np.asarray(verts, dtype=np.float64) @ R_ns.T
        f = np.asarray(faces)
        if f.ndim == 2 and f.shape[1] == 3:
            return v[f]
    return None


def plot_topdown(out_path: str | Path, *, nav_from_scene: np.ndarray, camera_centers: np.ndarray,
                 episodes: Sequence = (), navmesh=None, title: str = "", max_paths: int = 30,
                 seed: int = 0, dpi: int = 120) -> Path:
    """Write the top-down PNG (atomic) and return its path.

    camera_centers `[M, 3]` and every episode's positions are in the scene frame; `navmesh` is a
    `planners.NavMesh` (its triangles if it exposes them, else 20k random navigable points).
    A random but seeded sample of `max_paths` episodes is drawn so big sets stay readable.
    """
    matplotlib.use("Agg", force=False)
    R_ns = np.asarray(nav_from_scene, dtype=np.float64)
    cams = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3) @ R_ns.T
    fig, ax = plt.subplots(figsize=(8, 8))
    try:
        if navmesh is not None:
            tri = navmesh_triangles_nav(navmesh, R_ns)
            if tri is not None:
                ax.add_collection(PolyCollection(tri[:, :, :2], facecolors="0.85", edgecolors="0.7",
                                                 linewidths=0.2, label="navmesh"))
            else:
                pts = np.asarray(navmesh.random_navigable_points(20000, seed=seed), dtype=np.float64) @ R_ns.T
                ax.scatter(pts[:, 0], pts[:, 1], s=2.0, c="0.8", marker=".", linewidths=0, label="navmesh")
        if len(cams):
            # capture order, broken where consecutive cameras jump (separate drives / stereo sides)
            step = np.linalg.norm(np.diff(cams[:, :2], axis=0), axis=-1)
            gap = np.flatnonzero(step > max(3.0 * float(np.median(step)) if len(step) else 0.0, 2.0))
            line = np.insert(cams[:, :2], gap + 1, np.nan, axis=0)
            ax.plot(line[:, 0], line[:, 1], "-", color="tab:blue", lw=1.0, alpha=0.8, label="capture cameras")
            ax.scatter(cams[:, 0], cams[:, 1], s=4, color="tab:blue")
        eps = list(episodes)
        if len(eps) > max_paths:
            pick = np.sort(np.random.default_rng(seed).choice(len(eps), size=max_paths, replace=False))
            eps = [eps[i] for i in pick]
        if eps:
            cmap = plt.get_cmap("viridis")
            lines = [np.asarray(e.reference_path, dtype=np.float64)[:, :3] @ R_ns.T for e in eps]
            ax.add_collection(LineCollection([ln[:, :2] for ln in lines], colors=[cmap(i / max(1, len(eps) - 1))
                                             for i in range(len(eps))], linewidths=1.4, label="expert paths"))
            st = np.stack([ln[0] for ln in lines])
            go = np.stack([ln[-1] for ln in lines])
            ax.scatter(st[:, 0], st[:, 1], marker="o", s=18, color="tab:green", zorder=3, label="starts")
            ax.scatter(go[:, 0], go[:, 1], marker="*", s=50, color="tab:red", zorder=3, label="goals")
            for e, g in zip(eps, go):
                ax.add_patch(plt.Circle((g[0], g[1]), float(e.goals[0].radius), fill=False, color="tab:red",
                                        lw=0.5, alpha=0.5))
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("nav x (m)")
        ax.set_ylabel("nav y (m)")
        ax.set_title(title or "episodes (top-down, nav frame)")
        ax.legend(loc="upper right", fontsize=7, markerscale=2)
        out_path = Path(out_path)
        with atomic_path(out_path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return out_path
