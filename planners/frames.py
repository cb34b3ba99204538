"""Up axes and the nav frame (z up) of a scene frame: the one frame convention `planners/` needs.

Here so `planners` stands alone (it never imports `wanderland_nav`). `wanderland_nav.geometry` keeps
its own copy because DESIGN.md's layering forbids it any import (tests/test_layering.py);
tests/planners/test_raster.py checks that the two agree on every up axis.
"""

from __future__ import annotations

import numpy as np

UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


def parse_up_axis(up_axis: str, *, source: str = "up_axis") -> str:
    """Normalise an up-axis string ('y', '+Y', '-y', ...) or raise naming `source`."""
    if not isinstance(up_axis, str):
        raise ValueError(f"{source}: up axis must be a string like '+z' or '-y', got {up_axis!r}")
    s = up_axis.strip().lower()
    if s in ("x", "y", "z"):
        s = "+" + s
    if s not in UP_AXES:
        raise ValueError(f"{source}: unknown up axis {up_axis!r}; expected one of {UP_AXES}")
    return s


def nav_from_scene_rotation(up_axis: str) -> np.ndarray:
    """Rotation `[3, 3]` (float64, det +1) taking scene-frame vectors to the nav frame (z up).

    The choice of the horizontal axes is fixed per up axis so the mapping is reproducible:
    +z: identity; -z: 180 deg about x; +y: +90 deg about x (Recast, glTF); -y: -90 deg about x
    (COLMAP / Wanderland v1); +x: -90 deg about y; -x: +90 deg about y.
    """
    s = parse_up_axis(up_axis)
    table = {
        "+z": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "-z": [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
        "+y": [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
        "-y": [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
        "+x": [[0, 0, -1], [0, 1, 0], [1, 0, 0]],
        "-x": [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
    }
    return np.asarray(table[s], dtype=np.float64)
