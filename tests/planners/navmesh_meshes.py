"""Hand-built test meshes for the planners (nav frame z up unless rotated)."""

from __future__ import annotations

import numpy as np
import trimesh

from planners import NavMesh, NavMeshSettings


def quad(x0, y0, x1, y1, z) -> trimesh.Trimesh:
    """Horizontal rectangle at height z, facing up (+z)."""
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def box(x0, y0, z0, x1, y1, z1) -> trimesh.Trimesh:
    return trimesh.creation.box(bounds=[[x0, y0, z0], [x1, y1, z1]])


def concat(*meshes) -> trimesh.Trimesh:
    return trimesh.util.concatenate(list(meshes))


def l_floor() -> trimesh.Trimesh:
    """L-shaped floor slab, grid aligned: arm A [0,12]x[0,3], arm B [9,12]x[0,12], no walls."""
    return concat(quad(0, 0, 9, 3, 0.0), quad(9, 0, 12, 12, 0.0))


def room_with_pillars() -> trimesh.Trimesh:
    """12 x 12 m floor, 0.3 m walls 2.5 m high around it, three pillars inside."""
    walls = [box(-0.3, -0.3, 0, 12.3, 0, 2.5), box(-0.3, 12, 0, 12.3, 12.3, 2.5),
             box(-0.3, 0, 0, 0, 12, 2.5), box(12, 0, 0, 12.3, 12, 2.5)]
    pillars = [box(3, 3, 0, 5, 5, 2.5), box(7, 6, 0, 8.2, 10, 2.5), box(6.1, 1.3, 0, 9.4, 2.2, 2.5)]
    return concat(quad(0, 0, 12, 12, 0.0), *walls, *pillars)


def stairs(step: float) -> trimesh.Trimesh:
    """Lower floor [0,6]x[0,4] at z=0, then 4 treads of 1 m rising by `step`, then an upper floor."""
    parts = [quad(0, 0, 6, 4, 0.0)]
    for i in range(4):
        parts.append(box(6 + i, 0, 0, 7 + i, 4, step * (i + 1)))
    parts.append(box(10, 0, 0, 16, 4, step * 4))
    return concat(*parts)


def two_floors(ramp: bool) -> trimesh.Trimesh:
    """Ground [0,16]x[0,8] at z=0 and a deck [0,8]x[0,8] at z=4 above its west half (0.2 m slab);
    with `ramp`, a 20 degree ramp from the ground's east end up to the deck's east edge... placed
    alongside (y in [8,11]) so it does not cover the ground."""
    parts = [quad(0, 0, 16, 8, 0.0), box(0, 0, 3.8, 8, 8, 4.0)]
    if ramp:
        # ramp along -x from (19, y) at z=0 up to (8, y) at z=4, beside the ground floor (y 8..11)
        v = np.array([[19, 8, 0], [19, 11, 0], [8, 11, 4], [8, 8, 4]], float)
        parts.append(trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False))
        parts.append(box(0, 8, 3.8, 8, 11, 4.0))  # landing joining ramp and deck
        parts.append(quad(16, 0, 19, 11, 0.0))  # ground extension to the ramp foot
    return concat(*parts)


def bake(mesh, **kw) -> NavMesh:
    kw.setdefault("up_axis", "+z")
    return NavMesh.bake(mesh, NavMeshSettings(**kw))
