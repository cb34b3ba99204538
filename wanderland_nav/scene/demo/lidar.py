"""A LiDAR-like metric point cloud, cast from the capture rig along the trajectory.

A scanner with a -40..+25 deg vertical field of view (a rig LiDAR tilted to see the ground near
the walker) is fired from rig poses spaced densely along every path. Its returns are
exact first hits on the ground-truth mesh, so surfaces the rig never sees (roofs, the far side
of the facades, the inside of the planters) are absent exactly as in a real capture; returns
beyond `max_range` are dropped, and each range gets N(0, sigma) noise along its beam. Points are
coloured with the surface texture (as a camera-colourised LiDAR map would be).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import textures
from .layout import Layout
from .raycast import RayCaster

SENSOR_ABOVE_RIG = 0.25  # the LiDAR sits on top of the camera rig
CAST_BLOCK_RAYS = 1 << 21  # rays cast at once (whole scans): bounds the memory of a dense capture


@dataclass(frozen=True)
class ScanPattern:
    """A non-repetitive scan (Livox-like, as on hand-held mapping rigs): every scan fires `rays`
    beams at random directions, area-uniform over the elevation band. Scans are taken densely
    along the walk (every few decimetres), so the accumulated cloud covers the ground evenly
    instead of showing the concentric rings a few fixed spinning scans would leave."""

    rays: int = 3000
    elev_min_deg: float = -40.0
    elev_max_deg: float = 25.0

    def directions(self, rng: np.random.Generator) -> np.ndarray:
        """Unit beam directions `[rays, 3]` in a z-up sensor frame."""
        lo, hi = np.sin(np.deg2rad(self.elev_min_deg)), np.sin(np.deg2rad(self.elev_max_deg))
        sz = rng.uniform(lo, hi, self.rays)
        az = rng.uniform(0.0, 2 * np.pi, self.rays)
        c = np.sqrt(1.0 - sz * sz)
        return np.stack([c * np.cos(az), c * np.sin(az), sz], -1)


def scan(caster: RayCaster, layout: Layout, sensor_positions: np.ndarray, pattern: ScanPattern, max_range: float,
         noise_sigma: float, seed: int):
    """Fire `pattern` from each of `sensor_positions [S, 3]` (nav frame).

    Returns `xyz [N, 3] float64` (noisy), `rgb [N, 3] uint8`, the exact hit points `[N, 3]` and
    the hit triangle ids `[N]`; order is scan by scan, beam by beam (deterministic).
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 5151]))
    S = sensor_positions.shape[0]
    dirs = np.concatenate([pattern.directions(rng) for _ in range(S)])  # [S*R, 3]
    R = pattern.rays
    parts = []  # cast a block of scans at a time: only the kept returns of each block are held
    step = max(1, CAST_BLOCK_RAYS // R)
    for a in range(0, S, step):
        d_blk = dirs[a * R:(a + step) * R]
        o_blk = np.repeat(sensor_positions[a:a + step], R, axis=0)
        t_blk, tri_blk = caster.cast(o_blk, d_blk)
        k = np.flatnonzero((tri_blk >= 0) & (t_blk <= max_range))
        parts.append((t_blk[k], tri_blk[k], d_blk[k], o_blk[k]))
    t, tri, d, o = (np.concatenate([q[i] for q in parts]) for i in range(4)) if parts else (
        np.zeros(0), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    del parts, dirs
    exact = o + t[:, None] * d
    noisy = o + (t + rng.normal(0.0, noise_sigma, len(t)))[:, None] * d
    n = caster.normals[tri]
    col = textures.shade(layout.face_material[tri], exact, n, np.full(len(t), 0.02), layout.is_indoor(exact), seed,
                         layout.car_color)
    return noisy, np.round(col * 255).astype(np.uint8), exact, tri
