"""Polyline helpers for expert paths: length, dense resampling, headings. Batched numpy, no planner."""

from __future__ import annotations

import numpy as np


def polyline_length(points: np.ndarray) -> float:
    """3D length (metres) of a `[P, 3]` polyline; 0 for a single point."""
    p = np.asarray(points, dtype=np.float64)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=-1).sum()) if len(p) > 1 else 0.0


def resample_polyline(points: np.ndarray, step: float, *, horizontal: bool = False) -> np.ndarray:
    """Points every `step` metres of arc length along `[P, 3]`, plus the exact end point.

    `horizontal=True` measures arc length on x, y only (pass nav-frame points): the agent's
    0.25 m forward step is a ground-plane distance, whatever the path climbs.

    Returns `[L, 3]` with `L = floor(length / step) + 1` (+1 if the end is not already on the grid),
    so the expert takes `L - 1` moves of at most `step` each. Interpolation is linear between
    corners; callers re-project the result onto the navmesh surface for the heights.
    """
    if step <= 0:
        raise ValueError(f"resample_polyline: step must be > 0, got {step}")
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 1:
        return p.copy()
    seg = np.linalg.norm(np.diff(p[:, :2] if horizontal else p, axis=0), axis=-1)  # [P-1]
    cum = np.concatenate([[0.0], np.cumsum(seg)])  # [P]
    total = cum[-1]
    s = np.arange(0.0, total + 1e-9, step)  # [L]
    if total - s[-1] > 1e-6:
        s = np.append(s, total)
    else:
        s[-1] = total
    j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)  # segment of each sample
    t = np.where(seg[j] > 0, (s - cum[j]) / np.where(seg[j] > 0, seg[j], 1.0), 0.0)
    out = p[j] + t[:, None] * (p[j + 1] - p[j])
    out[0], out[-1] = p[0], p[-1]
    return out


def first_heading_nav(points_nav: np.ndarray, min_len: float = 1e-3) -> float:
    """Yaw (rad, nav frame) of the first path segment with horizontal length > `min_len`; 0 if none."""
    d = np.diff(np.asarray(points_nav, dtype=np.float64)[:, :2], axis=0)
    n = np.linalg.norm(d, axis=-1)
    k = np.flatnonzero(n > min_len)
    return float(np.arctan2(d[k[0], 1], d[k[0], 0])) if k.size else 0.0


def last_heading_nav(points_nav: np.ndarray, min_len: float = 1e-3) -> float:
    """Yaw (rad, nav frame) of the last path segment with horizontal length > `min_len`; 0 if none."""
    d = np.diff(np.asarray(points_nav, dtype=np.float64)[:, :2], axis=0)
    k = np.flatnonzero(np.linalg.norm(d, axis=-1) > min_len)
    return float(np.arctan2(d[k[-1], 1], d[k[-1], 0])) if k.size else 0.0
