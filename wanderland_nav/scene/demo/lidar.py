"""A LiDAR-like metric point cloud, cast from the capture rig along the trajectory.

A spinning multi-beam scanner (vertical field of view -40..+25 deg, as a rig LiDAR tilted to
see the ground near the walker) is fired from rig poses spaced along every path. Its returns are
exact first hits on the ground-truth mesh, so surfaces the rig never sees (roofs, the far side
of the facades, the inside of the planters) are absent exactly as in a real capture; returns
beyond `max_range` are dropped, and each range gets N(0, sigma) noise along its beam. Points are
coloured with the surface texture (as a camera-colourised LiDAR map would be).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import textures
from .layout import Layout, is_indoor_nav
from .raycast import RayCaster

SENSOR_ABOVE_RIG = 0.25  # the LiDAR sits on top of the camera rig


@dataclass(frozen=True)
class ScanPattern:
    beams: int = 48
    azimuth_steps: int = 720
    elev_min_deg: float = -40.0
    elev_max_deg: float = 25.0

    def directions(self, phase: float = 0.0) -> np.ndarray:
        """Unit beam directions `[beams * azimuth_steps, 3]` in a z-up sensor frame."""
        el = np.deg2rad(np.linspace(self.elev_min_deg, self.elev_max_deg, self.beams))
        az = (np.arange(self.azimuth_steps) + phase) * (2 * np.pi / self.azimuth_steps)
        E, A = np.meshgrid(el, az, indexing="ij")
        return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)


def scan(caster: RayCaster, layout: Layout, sensor_positions: np.ndarray, pattern: ScanPattern, max_range: float,
         noise_sigma: float, seed: int):
    """Fire `pattern` from each of `sensor_positions [S, 3]` (nav frame).

    Returns `xyz [N, 3] float64` (noisy), `rgb [N, 3] uint8`, the exact hit points `[N, 3]` and
    the hit triangle ids `[N]`; order is scan by scan, beam by beam (deterministic).
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 5151]))
    S = sensor_positions.shape[0]
    phases = rng.uniform(0.0, 1.0, S)  # each scan starts at a different sub-step azimuth
    dirs = np.concatenate([pattern.directions(ph) for ph in phases])  # [S*R, 3]
    R = pattern.beams * pattern.azimuth_steps
    orig = np.repeat(sensor_positions, R, axis=0)
    t, tri = caster.cast(orig, dirs)
    keep = np.flatnonzero((tri >= 0) & (t <= max_range))
    t, tri, d, o = t[keep], tri[keep], dirs[keep], orig[keep]
    exact = o + t[:, None] * d
    noisy = o + (t + rng.normal(0.0, noise_sigma, len(t)))[:, None] * d
    n = caster.normals[tri]
    col = textures.shade(layout.face_material[tri], exact, n, np.full(len(t), 0.02), is_indoor_nav(exact), seed,
                         layout.car_color)
    return noisy, np.round(col * 255).astype(np.uint8), exact, tri
