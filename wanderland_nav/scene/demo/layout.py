"""Procedural geometry of the demo urban block, built in a Z-up metric frame (the nav frame).

The block is about 60 x 40 m (x in [-30, 30], y in [-20, 20]; street and sidewalk run on to
x = +-40 so the views along the street do not end in a void):

* a street (z = 0) with a parked car, a kerb (0.15 m) up to a sidewalk (z = 0.15);
* a lower courtyard at sidewalk level and a raised plaza (z = 1.35, 1.2 m above it) reached by
  a ramp (about 9.7 deg) and by stairs with 7 risers of 0.171 m, so a navmesh with a 0.9 m
  max climb walks them and also meets a 1.2 m ledge it must not step down;
* a building with an open lobby: 0.3 m walls with three doorways, a partition wall with a door,
  a ceiling at 4.15 m, pillars and a desk (the indoor region), with more storeys above;
* street furniture: benches, lamp poles, trees whose canopy starts 2.7 m above the ground,
  planters, bollards, a lawn, a facade across the street and a garden wall behind the plaza.

Everything is a plain triangle soup with a material id per face, oriented outward (the normal
drives the shading). Faces that can never be seen (box bottoms resting on the ground) are left
out so the ground-truth mesh has no hidden area that would bias completeness metrics.
The seed only jitters details (tree shapes, car colour, furniture offsets): the structure, and
everything the tests and the capture path rely on, is the same for every seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import trimesh

from .textures import MATERIALS

M = {name: i for i, name in enumerate(MATERIALS)}

# --------------------------------------------------------------------------- fixed dimensions (metres, nav frame)
STREET_Z = 0.0
SIDEWALK_Z = 0.15  # kerb height
PLAZA_Z = 1.35  # 1.2 m above the courtyard
STREET_Y = (-20.0, -12.0)
CURB_Y = (-12.0, -11.8)
SIDEWALK_Y = (-11.8, -6.0)
X_LONG = (-40.0, 40.0)  # street and sidewalk extent
BLOCK_X = (-30.0, 30.0)
PLAZA = (-30.0, 4.0, 2.0, 20.0)  # x0, x1, y0, y1
STAIRS = (-14.0, -8.0)  # x range; risers climb towards +y, the top riser is the plaza edge y = 2
N_RISERS = 7
TREAD = 0.35
RAMP = (-26.0, -22.0, -5.0, 2.0)  # x0, x1, y0 (bottom, z = SIDEWALK_Z), y1 (top, z = PLAZA_Z)
BUILDING = (6.0, 28.0, -6.0, 14.0)  # outer footprint
WALL_T = 0.3
LOBBY_TOP = 4.15  # ceiling underside
BUILDING_TOP = 12.15
DOOR_H = 2.6
SOUTH_DOORS = ((10.0, 12.4), (20.0, 22.4))  # x ranges in the y = -6 wall
WEST_DOOR = (4.0, 6.4)  # y range in the x = 6 wall
PARTITION_Y = 9.0  # interior wall from the west wall to x = 20, door at x in PARTITION_DOOR
PARTITION_X1 = 20.0
PARTITION_DOOR = (14.0, 16.0)
PILLARS_XY = tuple((x, y) for x in (9.0, 17.5, 25.5) for y in (-1.5, 5.5))
PILLAR_HALF = 0.25
STAIR_RISE = (PLAZA_Z - SIDEWALK_Z) / N_RISERS


@dataclass
class Layout:
    """Triangle soup of the demo block (nav frame, z up, metres) plus the facts other parts need."""

    vertices: np.ndarray  # [V, 3] float64
    faces: np.ndarray  # [F, 3] int64, counter-clockwise seen from outside
    face_material: np.ndarray  # [F] int16 index into textures.MATERIALS
    car_color: np.ndarray  # [3] float, albedo of the car paint (seed dependent)
    indoor_regions: list[dict] = field(default_factory=list)  # scene_meta.json schema, nav frame (rectangles)
    walk_height: Callable[[np.ndarray], np.ndarray] | None = None  # xy [..., 2] -> ground height [...] (no furniture)

    def is_indoor(self, p: np.ndarray) -> np.ndarray:
        """`[..., 3]` nav-frame points -> bool `[...]`: inside an indoor region (its polygon's bounding
        rectangle, bounds included, and z_min <= z <= z_max). The generators write rectangular regions only."""
        p = np.asarray(p, np.float64)
        inside = np.zeros(p.shape[:-1], bool)
        for reg in self.indoor_regions:
            poly = np.asarray(reg["polygon_xy"], np.float64)
            lo, hi = poly.min(0), poly.max(0)
            inside |= ((p[..., 0] >= lo[0]) & (p[..., 0] <= hi[0]) & (p[..., 1] >= lo[1]) & (p[..., 1] <= hi[1])
                       & (p[..., 2] >= reg["z_min"]) & (p[..., 2] <= reg["z_max"]))
        return inside

    @property
    def face_normals(self) -> np.ndarray:
        """`[F, 3]` unit outward normals."""
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

def indoor_polygon() -> list[list[float]]:
    """Lobby interior (inside the outer walls), nav-frame xy, counter-clockwise."""
    x0, x1, y0, y1 = BUILDING
    e = 0.01  # include the inner wall faces themselves
    return [[x0 + WALL_T - e, y0 + WALL_T - e], [x1 - WALL_T + e, y0 + WALL_T - e],
            [x1 - WALL_T + e, y1 - WALL_T + e], [x0 + WALL_T - e, y1 - WALL_T + e]]


def is_indoor_nav(p: np.ndarray) -> np.ndarray:
    """`[..., 3]` nav-frame points -> bool `[...]`: inside the lobby (footprint and below its ceiling)."""
    poly = np.asarray(indoor_polygon())
    return ((p[..., 0] >= poly[0, 0]) & (p[..., 0] <= poly[1, 0]) & (p[..., 1] >= poly[0, 1])
            & (p[..., 1] <= poly[2, 1]) & (p[..., 2] >= SIDEWALK_Z - 0.5) & (p[..., 2] <= LOBBY_TOP + 0.01))


def walk_height(xy: np.ndarray) -> np.ndarray:
    """Walkable ground height `[...]` under nav-frame `xy [..., 2]` (ignores furniture).

    Used to put the capture rig at a fixed height above whatever it walks on.
    """
    x, y = xy[..., 0], xy[..., 1]
    z = np.full(x.shape, SIDEWALK_Z)
    z = np.where(y < CURB_Y[0], STREET_Z, z)
    px0, px1, py0, py1 = PLAZA
    z = np.where((x >= px0) & (x <= px1) & (y >= py0) & (y <= py1), PLAZA_Z, z)
    # stairs: tread k (1..6) spans y in [2 - (7-k) T, 2 - (6-k) T] at height SIDEWALK_Z + k * rise
    in_st = (x >= STAIRS[0]) & (x <= STAIRS[1]) & (y < py0) & (y >= py0 - (N_RISERS - 1) * TREAD)
    k = np.clip(N_RISERS - np.ceil((py0 - y) / TREAD), 1, N_RISERS - 1)
    z = np.where(in_st, SIDEWALK_Z + k * STAIR_RISE, z)
    rx0, rx1, ry0, ry1 = RAMP
    in_r = (x >= rx0) & (x <= rx1) & (y >= ry0) & (y < ry1)
    z = np.where(in_r, SIDEWALK_Z + (y - ry0) / (ry1 - ry0) * (PLAZA_Z - SIDEWALK_Z), z)
    return z


# --------------------------------------------------------------------------- mesh building


class Builder:
    """Accumulates oriented triangles with a material id each."""

    def __init__(self):
        self.v: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.m: list[np.ndarray] = []
        self.n = 0

    def add(self, verts, faces, material: int):
        verts = np.asarray(verts, np.float64)
        faces = np.asarray(faces, np.int64)
        self.v.append(verts)
        self.f.append(faces + self.n)
        self.m.append(np.full(len(faces), material, np.int16))
        self.n += len(verts)

    def poly(self, corners, normal, material: int):
        """Planar convex polygon (3 or 4 corners, any winding) oriented so its normal follows `normal`."""
        c = np.asarray(corners, np.float64)
        nrm = np.cross(c[1] - c[0], c[2] - c[0])
        if np.dot(nrm, normal) < 0:
            c = c[::-1]
        faces = [[0, 1, 2]] + ([[0, 2, 3]] if len(c) == 4 else [])
        self.add(c, faces, material)

    def rect(self, x0, x1, y0, y1, z, material: int, up: bool = True):
        """Horizontal rectangle at height z."""
        self.poly([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], [0, 0, 1 if up else -1], material)

    def vquad_x(self, x, y0, y1, z0, z1, material: int, sign: float):
        """Vertical rectangle in the plane x = const facing `sign` * x."""
        self.poly([[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]], [sign, 0, 0], material)

    def vquad_y(self, y, x0, x1, z0, z1, material: int, sign: float):
        self.poly([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], [0, sign, 0], material)

    def box(self, lo, hi, material, skip=("-z",), mats: dict | None = None):
        """Axis-aligned box; `skip` names faces never seen ('-z' = resting on the ground)."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        mats = mats or {}
        if "+z" not in skip:
            self.rect(x0, x1, y0, y1, z1, mats.get("+z", material))
        if "-z" not in skip:
            self.rect(x0, x1, y0, y1, z0, mats.get("-z", material), up=False)
        if "-x" not in skip:
            self.vquad_x(x0, y0, y1, z0, z1, mats.get("-x", material), -1)
        if "+x" not in skip:
            self.vquad_x(x1, y0, y1, z0, z1, mats.get("+x", material), +1)
        if "-y" not in skip:
            self.vquad_y(y0, x0, x1, z0, z1, mats.get("-y", material), -1)
        if "+y" not in skip:
            self.vquad_y(y1, x0, x1, z0, z1, mats.get("+y", material), +1)

    def trimesh_(self, mesh: trimesh.Trimesh, material: int):
        self.add(mesh.vertices, mesh.faces, material)

    def build(self):
        return np.concatenate(self.v), np.concatenate(self.f), np.concatenate(self.m)


def rect_minus(rect, holes):
    """Split an axis-aligned rectangle `(x0, x1, y0, y1)` into cells not covered by `holes`."""
    x0, x1, y0, y1 = rect
    xs = sorted({x0, x1, *[h[k] for h in holes for k in (0, 1) if x0 < h[k] < x1]})
    ys = sorted({y0, y1, *[h[k] for h in holes for k in (2, 3) if y0 < h[k] < y1]})
    out = []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            cx, cy = 0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1])
            if not any(h[0] <= cx <= h[1] and h[2] <= cy <= h[3] for h in holes):
                out.append((xs[i], xs[i + 1], ys[j], ys[j + 1]))
    return out


def wall_x(b: Builder, x0, x1, y0, y1, z0, z1, doors, material, inner_mat, inner_side):
    """Wall slab spanning x in [x0, x1] (thin in y) with door openings `doors` = [(a, b)] along x."""
    edges = [x0] + [v for d in doors for v in d] + [x1]
    for a, c in zip(edges[0::2], edges[1::2]):
        if c - a > 1e-6:
            b.box((a, y0, z0), (c, y1, z1), material, skip=("-z", "+z"), mats={inner_side: inner_mat})
    for a, c in doors:  # lintel above each door, its underside visible
        b.box((a, y0, z0 + DOOR_H), (c, y1, z1), material, skip=("-x", "+x", "+z"), mats={inner_side: inner_mat, "-z": M["plaster"]})


def wall_y(b: Builder, x0, x1, y0, y1, z0, z1, doors, material, inner_mat, inner_side):
    """Wall slab spanning y in [y0, y1] (thin in x) with door openings along y."""
    edges = [y0] + [v for d in doors for v in d] + [y1]
    for a, c in zip(edges[0::2], edges[1::2]):
        if c - a > 1e-6:
            b.box((x0, a, z0), (x1, c, z1), material, skip=("-z", "+z"), mats={inner_side: inner_mat})
    for a, c in doors:
        b.box((x0, a, z0 + DOOR_H), (x1, c, z1), material, skip=("-y", "+y", "+z"), mats={inner_side: inner_mat, "-z": M["plaster"]})


def tree(b: Builder, rng, x, y, z):
    b.box((x - 0.15, y - 0.15, z), (x + 0.15, y + 0.15, z + 3.2), M["bark"])
    # tree pit: a soil square flush with the paving (drawn 1 mm above it to win the depth test)
    b.rect(x - 0.7, x + 0.7, y - 0.7, y + 0.7, z + 0.001, M["soil"])
    s = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    d = s.vertices / np.linalg.norm(s.vertices, axis=1, keepdims=True)
    r = 1.0 + 0.18 * rng.standard_normal(len(d)).clip(-2, 2)
    radii = np.array([1.9, 1.9, 1.3]) * rng.uniform(0.9, 1.1)
    centre = np.array([x, y, z + 2.7 + radii[2]])  # canopy bottom 2.7 m above the ground
    verts = centre + d * r[:, None] * radii
    verts[:, 2] = np.maximum(verts[:, 2], z + 2.7)
    b.add(verts, s.faces, M["foliage"])


def bench(b: Builder, x, y, z, along_x: bool):
    L, W = 1.8, 0.5
    hx, hy = (L / 2, W / 2) if along_x else (W / 2, L / 2)
    b.box((x - hx, y - hy, z + 0.42), (x + hx, y + hy, z + 0.48), M["wood"], skip=())
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, cy = x + sx * (hx - 0.08), y + sy * (hy - 0.08)
            b.box((cx - 0.03, cy - 0.03, z), (cx + 0.03, cy + 0.03, z + 0.42), M["metal"])
    if along_x:  # backrest on the +y side
        b.box((x - hx, y + hy - 0.05, z + 0.5), (x + hx, y + hy, z + 0.9), M["wood"], skip=())
    else:
        b.box((x + hx - 0.05, y - hy, z + 0.5), (x + hx, y + hy, z + 0.9), M["wood"], skip=())


def pole(b: Builder, x, y, z, h=5.5):
    c = trimesh.creation.cylinder(radius=0.07, height=h, sections=10)
    c.apply_translation((x, y, z + h / 2))
    b.trimesh_(c, M["metal"])
    b.box((x - 0.35, y - 0.15, z + h), (x + 0.35, y + 0.15, z + h + 0.18), M["metal"], skip=())


def planter(b: Builder, x, y, z, rng):
    b.box((x - 0.6, y - 0.6, z), (x + 0.6, y + 0.6, z + 0.6), M["terracotta"], skip=("-z", "+z"))
    b.rect(x - 0.6, x + 0.6, y - 0.6, y + 0.6, z + 0.5, M["soil"])
    s = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    s.vertices *= 1 + 0.15 * rng.standard_normal((len(s.vertices), 1)).clip(-2, 2)
    s.apply_translation((x, y, z + 0.85))
    b.trimesh_(s, M["foliage"])


def car(b: Builder, x0, x1, yc, z):
    w = 1.8
    b.box((x0, yc - w / 2, z + 0.3), (x1, yc + w / 2, z + 1.0), M["car_paint"], skip=())
    L = x1 - x0
    cab = (x0 + 0.25 * L, x0 + 0.78 * L)
    b.box((cab[0], yc - 0.78, z + 1.0), (cab[1], yc + 0.78, z + 1.5), M["glass"], skip=("-z",),
          mats={"+z": M["car_paint"]})
    for wx in (x0 + 0.75, x1 - 0.75):
        for side in (-1, 1):
            c = trimesh.creation.cylinder(radius=0.33, height=0.25, sections=14)
            c.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
            c.apply_translation((wx, yc + side * (w / 2 - 0.1), z + 0.33))
            b.trimesh_(c, M["rubber"])


TREE_X = (-19.0, -6.0, 8.0, 21.0)  # street trees along the sidewalk (pits in the paving)


def _ground_levels(b: "Builder") -> None:
    """Street, kerb, sidewalk, the courtyard level, the plaza, its stairs and ramp."""
    lx0, lx1 = X_LONG
    # ---- street, kerb, sidewalk
    b.rect(lx0, lx1, STREET_Y[0], STREET_Y[1], STREET_Z, M["asphalt"])
    b.vquad_y(CURB_Y[0], lx0, lx1, STREET_Z, SIDEWALK_Z, M["granite"], -1)
    b.rect(lx0, lx1, CURB_Y[0], CURB_Y[1], SIDEWALK_Z, M["granite"])
    pits = [(x - 0.7, x + 0.7, -10.7 - 0.7, -10.7 + 0.7) for x in TREE_X]
    for r in rect_minus((lx0, lx1, SIDEWALK_Y[0], SIDEWALK_Y[1]), pits):
        b.rect(*r, SIDEWALK_Z, M["paving"])
    # ---- lower level north of the sidewalk (courtyard, strips around the building)
    bx0, bx1, by0, by1 = BUILDING
    px0, px1, py0, py1 = PLAZA
    rx0, rx1, ry0, ry1 = RAMP
    stairs_fp = (STAIRS[0], STAIRS[1], py0 - (N_RISERS - 1) * TREAD, py0)
    holes = [PLAZA, BUILDING, (rx0, rx1, ry0, ry1), stairs_fp]
    for r in rect_minus((BLOCK_X[0], BLOCK_X[1], SIDEWALK_Y[1], 20.0), holes):
        b.rect(*r, SIDEWALK_Z, M["paving"])
    # lobby floor
    b.rect(bx0, bx1, by0, by1, SIDEWALK_Z, M["lobby_floor"])
    # ---- plaza: top (stone with a lawn), retaining faces
    lawn = (-28.5, -17.0, 15.0, 19.0)
    for r in rect_minus(PLAZA, [lawn]):
        b.rect(*r, PLAZA_Z, M["plaza_stone"])
    b.rect(*lawn, PLAZA_Z, M["grass"])
    front = [(px0, rx0), (rx1, STAIRS[0]), (STAIRS[1], px1)]
    for a, c in front:
        b.vquad_y(py0, a, c, SIDEWALK_Z, PLAZA_Z, M["concrete"], -1)
    b.vquad_x(px1, py0, py1, SIDEWALK_Z, PLAZA_Z, M["concrete"], +1)
    # ---- stairs: treads and risers, side faces as one rectangle per step column
    for k in range(1, N_RISERS + 1):
        y_r = py0 - (N_RISERS - k) * TREAD  # riser k at this y, from height k-1 to k
        z_lo, z_hi = SIDEWALK_Z + (k - 1) * STAIR_RISE, SIDEWALK_Z + k * STAIR_RISE
        b.vquad_y(y_r, STAIRS[0], STAIRS[1], z_lo, z_hi, M["concrete"], -1)
        if k < N_RISERS:
            b.rect(STAIRS[0], STAIRS[1], y_r, y_r + TREAD, z_hi, M["concrete"])
            for xs, sgn in ((STAIRS[0], -1), (STAIRS[1], +1)):
                b.vquad_x(xs, y_r, y_r + TREAD, SIDEWALK_Z, z_hi, M["concrete"], sgn)
    # ---- ramp: sloped top and two triangular sides
    b.poly([[rx0, ry0, SIDEWALK_Z], [rx1, ry0, SIDEWALK_Z], [rx1, ry1, PLAZA_Z], [rx0, ry1, PLAZA_Z]],
           [0, -(PLAZA_Z - SIDEWALK_Z), ry1 - ry0], M["concrete"])
    for xs, sgn in ((rx0, -1), (rx1, +1)):
        b.poly([[xs, ry0, SIDEWALK_Z], [xs, ry1, SIDEWALK_Z], [xs, ry1, PLAZA_Z]], [sgn, 0, 0], M["concrete"])


def _building(b: "Builder") -> None:
    """The lobby: exterior walls with doorways, partition, pillars, desk, ceiling, upper block."""
    bx0, bx1, by0, by1 = BUILDING
    # ---- building: exterior walls with doorways, partition, pillars, desk, ceiling, upper block
    z0, zt = SIDEWALK_Z, LOBBY_TOP
    wall_x(b, bx0, bx1, by0, by0 + WALL_T, z0, zt, SOUTH_DOORS, M["brick"], M["plaster"], "+y")
    wall_x(b, bx0, bx1, by1 - WALL_T, by1, z0, zt, [], M["brick"], M["plaster"], "-y")
    wall_y(b, bx0, bx0 + WALL_T, by0 + WALL_T, by1 - WALL_T, z0, zt, [WEST_DOOR], M["brick"], M["plaster"], "+x")
    wall_y(b, bx1 - WALL_T, bx1, by0 + WALL_T, by1 - WALL_T, z0, zt, [], M["brick"], M["plaster"], "-x")
    wall_x(b, bx0 + WALL_T, PARTITION_X1, PARTITION_Y - 0.1, PARTITION_Y + 0.1, z0, zt, [PARTITION_DOOR],
            M["plaster"], M["plaster"], "+y")
    for x, y in PILLARS_XY:
        b.box((x - PILLAR_HALF, y - PILLAR_HALF, z0), (x + PILLAR_HALF, y + PILLAR_HALF, zt), M["concrete"], skip=("-z", "+z"))
    b.box((22.0, 9.8, z0), (26.0, 10.6, z0 + 1.05), M["wood"])  # reception desk
    b.box((bx0, by0, zt), (bx1, by1, BUILDING_TOP), M["facade"], mats={"-z": M["ceiling"], "+z": M["concrete"]}, skip=())


def _backdrop(b: "Builder") -> None:
    """Facade across the street, garden wall, neighbouring blocks closing the courtyard level."""
    lx0, lx1 = X_LONG
    px0, px1 = PLAZA[0], PLAZA[1]
    # ---- backdrop: facade across the street, garden wall behind the plaza and the building
    b.vquad_y(STREET_Y[0], lx0, lx1, STREET_Z, 14.0, M["facade"], +1)
    b.box((px0, 20.0, PLAZA_Z), (px1, 20.4, PLAZA_Z + 2.4), M["brick"], skip=("-z", "+y"))
    b.box((px1, 20.0, SIDEWALK_Z), (BLOCK_X[1], 20.4, SIDEWALK_Z + 3.6), M["brick"], skip=("-z", "+y"))
    # neighbouring blocks closing the courtyard level at x = +-30 (their outer faces are never seen)
    b.box((BLOCK_X[1], SIDEWALK_Y[1], SIDEWALK_Z), (X_LONG[1], 20.4, 10.0), M["facade"], skip=("-z", "+x", "+y"))
    b.box((X_LONG[0], SIDEWALK_Y[1], SIDEWALK_Z), (BLOCK_X[0], 20.4, 10.0), M["facade"], skip=("-z", "-x", "+y"))


def _furniture(b: "Builder", rng: np.random.Generator) -> None:
    """Trees, poles, benches, planters, bollards and the car (the seed jitters positions)."""
    j = lambda s=0.25: float(rng.uniform(-s, s))  # noqa: E731
    for x in TREE_X:
        tree(b, rng, x + 0.0, -10.7, SIDEWALK_Z)
    for x, y in ((-24.0, 11.0), (-2.0, 11.5)):
        tree(b, rng, x + j(0.3), y + j(0.3), PLAZA_Z)
    for x in (-25.0, -12.0, 1.0, 14.0, 27.0):
        pole(b, x + j(0.2), -11.45, SIDEWALK_Z)
    for x, y, along in ((-16.0 + j(), -6.9, True), (-1.0 + j(), -6.9, True), (-18.0 + j(), 9.0, True),
                        (-7.0 + j(), 14.5, True), (2.6, 6.0 + j(), False)):
        bench(b, x, y, walk_height(np.array([x, y])).item(), along)
    for x, y in ((-20.0, 6.0), (-4.0, 6.0), (0.0, 16.0)):  # on the plaza
        planter(b, x + j(0.2), y + j(0.2), PLAZA_Z, rng)
    for x, y in ((-3.0, -3.5), (3.0, -1.0), (29.0, 0.0)):
        planter(b, x + j(0.2), y + j(0.2), SIDEWALK_Z, rng)
    for x in (-3.0, -1.5, 3.0, 4.5):  # bollards at the courtyard entrance
        c = trimesh.creation.cylinder(radius=0.1, height=0.9, sections=10)
        c.apply_translation((x, -6.6, SIDEWALK_Z + 0.45))
        b.trimesh_(c, M["metal"])
    car_x0 = -10.0 + j(0.5)
    car(b, car_x0, car_x0 + 4.4, -13.3, STREET_Z)


def build_layout(seed: int = 0) -> Layout:
    """The demo block for `seed` (structure fixed; seed jitters details only)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7301]))
    b = Builder()
    _ground_levels(b)
    _building(b)
    _backdrop(b)
    _furniture(b, rng)
    V, F, Mt = b.build()
    palette = np.array([[0.62, 0.08, 0.07], [0.08, 0.22, 0.55], [0.85, 0.85, 0.82], [0.15, 0.35, 0.2]])
    car_color = palette[int(rng.integers(len(palette)))]
    regions = [{"polygon_xy": indoor_polygon(), "z_min": SIDEWALK_Z - 0.5, "z_max": LOBBY_TOP + 0.01}]
    return Layout(V, F, Mt, car_color, regions, walk_height)
