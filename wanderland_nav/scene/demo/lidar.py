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
    orig = np.repeat(sensor_positions, R, axis=0)
    t, tri = caster.cast(orig, dirs)
    keep = np.flatnonzero((tri >= 0) & (t <= max_range))
    t, tri, d, o = t[keep], tri[keep], dirs[keep], orig[keep]
    exact = o + t[:, None] * d
    noisy = o + (t + rng.normal(0.0, noise_sigma, len(t)))[:, None] * d
    n = caster.normals[tri]
    col = textures.shade(layout.face_material[tri], exact, n, np.full(len(t), 0.02), layout.is_indoor(exact), seed,
                         layout.car_color)
    return noisy, np.round(col * 255).astype(np.uint8), exact, tri
