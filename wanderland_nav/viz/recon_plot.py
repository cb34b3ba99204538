"""Top-down PNG of a reconstruction benchmark scene: ground truth vs the aligned prediction.

Why: a wrong frame convention (world-to-camera read as camera-to-world), a mirrored trajectory or
a scale collapse is obvious in this picture long before it is obvious in an RMSE. The view is
from "above": along `up` when the caller knows the up axis (a scene), else along the direction
in which the ground-truth centres vary least (PCA), which is the vertical for any trajectory
that mostly moves on a floor. Grey segments join every matched pair (the per-camera error).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from wanderland_nav.atomic import atomic_path


def plane_axes(gt: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """`[2, 3]` orthonormal axes of the viewing plane (rows), right-handed with the view direction."""
    gt = np.asarray(gt, dtype=np.float64)
    if up is None:
        _, _, Vt = np.linalg.svd(gt - gt.mean(0), full_matrices=True)
        a, b = Vt[0], Vt[1]
    else:
        n = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
    return np.stack([a, b])


def plot_trajectories(out_path, gt: np.ndarray, pred: np.ndarray, *, up: np.ndarray | None = None,
                      title: str = "", pred_label: str = "prediction (Sim(3)-aligned)", dpi: int = 120) -> Path:
    """Write the PNG (atomic) for matched centres `gt [M,3]`, `pred [M,3]` (already aligned) and return its path."""
    matplotlib.use("Agg", force=False)
    A = plane_axes(gt, up)
    g2, p2 = np.asarray(gt) @ A.T, np.asarray(pred) @ A.T  # [M,2]
    fig, ax = plt.subplots(figsize=(7, 7))
    try:
        ax.add_collection(LineCollection(np.stack([g2, p2], 1), colors="0.6", linewidths=0.5, label="error"))
        ax.plot(g2[:, 0], g2[:, 1], "-", color="tab:green", lw=1.2, label="ground truth")
        ax.plot(p2[:, 0], p2[:, 1], "-", color="tab:red", lw=1.0, alpha=0.85, label=pred_label)
        ax.scatter(g2[:1, 0], g2[:1, 1], marker="o", s=30, color="k", zorder=3, label="first camera")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("m")
        ax.set_ylabel("m")
        ax.set_title(title or "trajectory (top-down)")
        ax.legend(loc="best", fontsize=8)
        with atomic_path(out_path) as tmp:  # no "Software" stamp: same input, same bytes
            fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return Path(out_path)
