"""The capture trajectory: a handheld stereo rig walked like the Wanderland protocol.

Two closed training loops (street/courtyard/stairs/plaza/ramp, and sidewalk/lobby/back room)
with a left/right camera pair 0.3 m apart at 1.5 m above the walked surface, plus an
extrapolation path (along the street centre and the plaza's back edge) whose viewpoints are
metres away from the training loops: its images form the `val` split. The rig faces along its
direction of travel; heading is a central difference over a 1.5 m chord, so corners turn
smoothly, and height follows the ground through a 1 m moving average (stairs are climbed
smoothly, not in 17 cm jumps). Small seeded jitter imitates a hand-held rig.
All poses are in the nav frame (z up); cameras use OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wanderland_nav.geometry import pinhole_intrinsics

from .layout import walk_height


@dataclass(frozen=True)
class CapturePath:
    name: str
    split: str  # "train" | "val"
    waypoints: tuple  # ((x, y), ...) nav frame
    closed: bool


PATHS = (
    CapturePath("loop_plaza", "train", ((-27.0, -8.5), (0.5, -8.5), (0.5, -2.0), (-11.0, -2.0), (-11.0, 12.5),
                                         (-21.0, 12.5), (-24.0, 9.0), (-24.0, -5.0)), True),
    CapturePath("loop_lobby", "train", ((4.0, -8.5), (11.2, -8.5), (11.2, 4.0), (15.0, 4.0), (15.0, 11.5),
                                         (21.5, 11.5), (21.5, 4.0), (21.2, -8.5)), True),
    CapturePath("street", "val", ((-29.0, -15.8), (29.0, -15.8)), False),
    CapturePath("plaza_back", "val", ((-27.0, 17.6), (2.0, 17.6)), False),
)

RIG_HEIGHT = 1.5
BASELINE = 0.3
PITCH = np.deg2rad(-4.0)  # slightly down, as a hand-held rig is usually carried


@dataclass
class Rig:
    """P rig poses along the paths (nav frame)."""

    position: np.ndarray  # [P, 3] rig centre (between the cameras)
    yaw: np.ndarray  # [P] heading about +z, radians
    pitch: np.ndarray  # [P]
    roll: np.ndarray  # [P]
    path_index: np.ndarray  # [P] index into the paths walked
    split: np.ndarray  # [P] "train" | "val"


def _polyline(points: np.ndarray, closed: bool):
    pts = np.vstack([points, points[:1]]) if closed else points
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return pts, cum


def _at(pts, cum, s):
    """Points `[K, 2]` at arc lengths `s [K]` (clamped to the polyline)."""
    s = np.clip(s, 0.0, cum[-1])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2)
    t = (s - cum[i]) / np.maximum(cum[i + 1] - cum[i], 1e-12)
    return pts[i] + t[:, None] * (pts[i + 1] - pts[i])


def sample_path(path: CapturePath, spacing: float, ground_height=walk_height) -> tuple[np.ndarray, np.ndarray]:
    """Positions `[K, 3]` (rig height applied), yaw `[K]` every ~`spacing` metres along a path;
    `ground_height(xy [..., 2]) -> [...]` is the walked surface (default: the demo block's)."""
    pts, cum = _polyline(np.asarray(path.waypoints, np.float64), path.closed)
    L = cum[-1]
    if path.closed:
        k = max(int(round(L / spacing)), 3)
        s = np.arange(k) * (L / k)
        wrap = lambda x: np.mod(x, L)  # noqa: E731
    else:
        k = max(int(np.floor(L / spacing)) + 1, 2)
        s = np.linspace(0.0, L, k)
        wrap = lambda x: x  # noqa: E731
    ahead, behind = _at(pts, cum, wrap(s + 0.75)), _at(pts, cum, wrap(s - 0.75))
    d = ahead - behind
    yaw = np.arctan2(d[:, 1], d[:, 0])
    xy = _at(pts, cum, s)
    offs = np.linspace(-0.5, 0.5, 11)  # ground height averaged over 1 m of path
    ground = ground_height(_at(pts, cum, wrap((s[:, None] + offs[None]).ravel())).reshape(-1, len(offs), 2)).mean(1)
    return np.column_stack([xy, ground + RIG_HEIGHT]), yaw


def make_rig(spacing: float, seed: int, val_spacing: float | None = None, paths=PATHS, ground_height=walk_height) -> Rig:
    """All rig poses along `paths` (default: the demo block's): training loops every `spacing` m, val paths every
    `val_spacing` (default = spacing), at `RIG_HEIGHT` above `ground_height`."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 4242]))
    pos, yaw, idx, split = [], [], [], []
    for i, p in enumerate(paths):
        x, a = sample_path(p, spacing if p.split == "train" else (val_spacing or spacing), ground_height)
        pos.append(x)
        yaw.append(a)
        idx.append(np.full(len(x), i))
        split += [p.split] * len(x)
    pos, yaw = np.concatenate(pos), np.concatenate(yaw)
    P = len(pos)
    pos = pos + np.column_stack([np.zeros((P, 2)), rng.normal(0, 0.02, P)])
    yaw = yaw + rng.normal(0, np.deg2rad(1.5), P)
    pitch = PITCH + rng.normal(0, np.deg2rad(1.5), P)
    roll = rng.normal(0, np.deg2rad(1.0), P)
    return Rig(pos, yaw, pitch, roll, np.concatenate(idx), np.asarray(split))


def rig_rotation(yaw, pitch, roll) -> np.ndarray:
    """`[P, 3, 3]` world_from_cam rotations (OpenCV camera axes) for heading/pitch/roll arrays `[P]`."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    fwd = np.stack([cy * cp, sy * cp, sp], -1)
    right0 = np.stack([sy, -cy, np.zeros_like(yaw)], -1)
    down0 = np.cross(fwd, right0)
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    right = cr * right0 + sr * down0  # roll about the optical axis
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd], -1)  # columns: camera x, y, z in the world


def stereo_cameras(rig: Rig, baseline: float = BASELINE):
    """Left/right `world_from_cam [2P, 4, 4]` (nav frame), sides `[2P]`, frame index `[2P]`.

    Order: for each rig pose, its left camera then its right camera.
    """
    R = rig_rotation(rig.yaw, rig.pitch, rig.roll)  # [P, 3, 3]
    right = R[:, :, 0]
    P = len(rig.position)
    T = np.tile(np.eye(4), (2 * P, 1, 1))
    T[0::2, :3, :3] = R
    T[1::2, :3, :3] = R
    T[0::2, :3, 3] = rig.position - 0.5 * baseline * right
    T[1::2, :3, 3] = rig.position + 0.5 * baseline * right
    sides = np.array(["left", "right"] * P)
    frame = np.repeat(np.arange(P), 2)
    return T, sides, frame


def intrinsics(size: int, hfov_deg: float = 90.0) -> np.ndarray:
    """Square pinhole `K [3, 3]` (Wanderland's undistorted views are square, 90 deg)."""
    return pinhole_intrinsics(size, size, hfov_deg)
