"""The expert moves path corners away from the obstacle they wrap, but never through another obstacle
(demo episode 68: an eased corner sent the route through a wall wedge and the expert stalled there)."""

from __future__ import annotations

import numpy as np
import torch

from wanderland_nav.envs.experts import ExpertPolicy

WALL = np.array([[4.5, 5.15], [5.5, 5.15]])  # a thin wall just outside the turn at (5, 5)


def _crossing(a, b):
    """Parameter t in [0, 1] where segment a->b crosses WALL, or None."""
    p, r = a[:2], b[:2] - a[:2]
    q, s = WALL[0], WALL[1] - WALL[0]
    den = r[0] * s[1] - r[1] * s[0]
    if abs(den) < 1e-12:
        return None
    t = ((q - p)[0] * s[1] - (q - p)[1] * s[0]) / den
    u = ((q - p)[0] * r[1] - (q - p)[1] * r[0]) / den
    return t if 0 <= t <= 1 and 0 <= u <= 1 else None


class WalledRoom:
    """A 10 m square room with one thin wall: `_navigable` and `_move` as NavEnv's (nav frame)."""

    def _navigable(self, p):
        p = p.numpy()
        return torch.as_tensor((p[:, 0] >= 0) & (p[:, 0] <= 10) & (p[:, 1] >= 0) & (p[:, 1] <= 10))

    def _move(self, a, b):
        a, b = a.numpy().astype(np.float64), b.numpy().astype(np.float64)
        end = b.copy()
        for i in range(len(a)):
            t = _crossing(a[i], b[i])
            if t is not None:
                end[i] = a[i] + (t - 1e-3) * (b[i] - a[i])
        return torch.as_tensor(end), torch.as_tensor(np.any(end != b, axis=1))


def test_eased_corner_steps_down_until_its_segments_are_walkable():
    path = np.array([[1.0, 1.0, 0.0], [5.0, 5.0, 0.0], [9.0, 1.0, 0.0]])  # turns at (5, 5), inside below
    eased = ExpertPolicy._ease_corners(WalledRoom(), path)
    # 0.3 and 0.2 m up would cross the wall at y = 5.15; 0.1 m keeps both segments clear
    np.testing.assert_allclose(eased[1, :2], [5.0, 5.1], atol=1e-9)
    assert ExpertPolicy._walkable(WalledRoom(), eased[:-1], eased[1:]).all()


def test_corner_without_a_wall_nearby_moves_by_the_largest_offset():
    path = np.array([[1.0, 1.0, 0.0], [5.0, 3.0, 0.0], [9.0, 1.0, 0.0]])
    eased = ExpertPolicy._ease_corners(WalledRoom(), path)
    np.testing.assert_allclose(eased[1, :2], [5.0, 3.3], atol=1e-9)
