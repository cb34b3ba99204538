"""Procedural geometry of an urban district, built from a seed in a Z-up metric frame (the nav frame).

A district is a W x H rectangle (5,000-10,000 m^2; x in [0, W], y in [0, H]) closed by facades at its
edge. From the seed come, in this order:

* the street network: one or two streets each way at jittered positions, some of their segments
  removed (T-junctions, dead ends, two blocks merged into one), one street sometimes pedestrian
  (paved, no kerb); roads at z = 0 with kerbs (0.15 m) up to 3 m sidewalks, zebra crossings at the
  junctions, street trees and lamp poles on the sidewalks, cars parked along the kerbs;
* the blocks between the streets, each one of: an enterable building (a lobby or a pillared hall,
  sometimes behind an arcade) with a second door, a plaza on one or two terraces (0.6-2 m each, up to
  ~3.8 m above the sidewalk) reached by wide ramps (6 deg) and stairs (risers <= 0.14 m), a park (lawn,
  ring path, trees, benches), or a closed building with a forecourt. Every district has at least one
  of the first three kinds;
* the capture paths: a closed loop around every block (on its sidewalks, inside it along the district
  edge), loops into the buildings, over the terraces and round the parks (train), and one path along
  every street's centre line (the extrapolation views, val).

Each block is built in its own frame (the block spans [0, w] x [0, d], its front on a street at y = 0)
and turned into place by quarter turns, so every block kind is written once. The walked surface is
painted into a height field as the geometry is made (`HeightField`), which puts the capture rig at its
height above ramps, stairs and terraces.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..demo.capture import CapturePath
from ..demo.layout import Builder, Layout, M, bench, car, planter, pole, tree, wall_x, wall_y

ROAD_W = 6.5
SIDEWALK_W = 3.0
CORRIDOR = ROAD_W + 2 * SIDEWALK_W
BASE = 0.15  # sidewalk / block level (kerb height above the road)
MIN_BLOCK = 20.0
# ramps 6 deg and as wide as the terrace beside its stairs: the collision mesh's ground step classifies a
# column as ground within 0.3 m (+10 % grade) of the lowest ground 3 m around it, so a narrow ramp beside
# the lower level, or a steeper one, loses its upper half and the terrace becomes an island
RAMP_TAN = float(np.tan(np.deg2rad(6.0)))
MAX_RISE = 0.14
TREAD = 0.35
WALL_T = 0.3
LOOP_OFFSET = 1.5  # block loops run this far outside the block (on the sidewalk), inside along the district edge
EDGE_MARGIN = 3.5  # clear strip kept inside a block along the district edge
HF_RES = 0.05


# --------------------------------------------------------------------------- frames and the height field


@dataclass(frozen=True)
class Frame:
    """A block's frame: world = R(k quarter turns) @ local + origin (z unchanged)."""

    ox: float
    oy: float
    k: int

    def _r(self):
        c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][self.k % 4]
        return np.array([[c, -s], [s, c]], np.float64)

    def xy(self, p):
        p = np.asarray(p, np.float64)
        return p @ self._r().T + np.array([self.ox, self.oy])

    def local(self, p):
        return (np.asarray(p, np.float64) - np.array([self.ox, self.oy])) @ self._r()

    def rect(self, x0, x1, y0, y1):
        c = self.xy([[x0, y0], [x1, y1]])
        return (min(c[:, 0]), max(c[:, 0]), min(c[:, 1]), max(c[:, 1]))

    def place(self, dst: Builder, src: Builder) -> None:
        if not src.v:
            return
        V, F, Mt = src.build()
        V = V.copy()
        V[:, :2] = self.xy(V[:, :2])
        dst.v.append(V)
        dst.f.append(F + dst.n)
        dst.m.append(Mt)
        dst.n += len(V)


class HeightField:
    """Walked-surface height on a `HF_RES` grid over the district (furniture ignored)."""

    def __init__(self, W: float, H: float):
        self.nx, self.ny = int(np.ceil(W / HF_RES)) + 1, int(np.ceil(H / HF_RES)) + 1
        self.z = np.full((self.ny, self.nx), BASE, np.float32)

    def paint(self, frame: Frame, x0, x1, y0, y1, fn) -> None:
        """Set the cells whose centres fall in the local rectangle to `fn(x_local, y_local)`."""
        X0, X1, Y0, Y1 = frame.rect(x0, x1, y0, y1)
        i0, i1 = max(int(np.floor(X0 / HF_RES)), 0), min(int(np.ceil(X1 / HF_RES)), self.nx)
        j0, j1 = max(int(np.floor(Y0 / HF_RES)), 0), min(int(np.ceil(Y1 / HF_RES)), self.ny)
        if i1 <= i0 or j1 <= j0:
            return
        gx, gy = np.meshgrid((np.arange(i0, i1) + 0.5) * HF_RES, (np.arange(j0, j1) + 0.5) * HF_RES)
        loc = frame.local(np.stack([gx, gy], -1).reshape(-1, 2))
        lx, ly = loc[:, 0], loc[:, 1]
        inside = ((lx >= x0) & (lx <= x1) & (ly >= y0) & (ly <= y1)).reshape(gx.shape)
        z = np.asarray(np.broadcast_to(fn(lx, ly), lx.shape), np.float32).reshape(gx.shape)
        block = self.z[j0:j1, i0:i1]
        block[inside] = z[inside]

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64)
        i = np.clip((xy[..., 0] / HF_RES).astype(np.int64), 0, self.nx - 1)
        j = np.clip((xy[..., 1] / HF_RES).astype(np.int64), 0, self.ny - 1)
        return self.z[j, i].astype(np.float64)


WORLD = Frame(0.0, 0.0, 0)


def emit_cells(b: Builder, rects, bounds) -> list:
    """Ground made of overlapping rectangles `(x0, x1, y0, y1, priority, material | None, z)`: the plane is cut
    on every rectangle edge, each cell takes the highest-priority rectangle over it (None: left open) and runs
    of equal cells along x become one quad. Returns the cells' winning rectangle `[ny, nx]` (-1: none) and the
    cut positions `xs [nx + 1]`, `ys [ny + 1]`."""
    bx0, bx1, by0, by1 = bounds
    xs = np.unique(np.clip([bx0, bx1, *[r[k] for r in rects for k in (0, 1)]], bx0, bx1))
    ys = np.unique(np.clip([by0, by1, *[r[k] for r in rects for k in (2, 3)]], by0, by1))
    cx, cy = 0.5 * (xs[:-1] + xs[1:]), 0.5 * (ys[:-1] + ys[1:])
    R = np.array([r[:5] for r in rects], np.float64)  # [K, 5]
    inx = (cx[None, :] >= R[:, 0:1]) & (cx[None, :] <= R[:, 1:2])  # [K, nx]
    iny = (cy[None, :] >= R[:, 2:3]) & (cy[None, :] <= R[:, 3:4])  # [K, ny]
    cover = iny[:, :, None] & inx[:, None, :]  # [K, ny, nx]
    prio = np.where(cover, R[:, 4, None, None], -np.inf)
    winner = np.where(np.isfinite(prio.max(0)), prio.argmax(0), -1)  # [ny, nx] index into rects
    for j in range(len(cy)):
        row = winner[j]
        i = 0
        while i < len(row):
            k = i
            while k + 1 < len(row) and row[k + 1] == row[i]:
                k += 1
            r = rects[row[i]] if row[i] >= 0 else None
            if r is not None and r[5] is not None:
                b.rect(xs[i], xs[k + 1], ys[j], ys[j + 1], r[6], M[r[5]])
            i = k + 1
    return winner, xs, ys


# --------------------------------------------------------------------------- the street network


@dataclass
class Street:
    axis: str  # "v": along y at x = pos; "h": along x at y = pos
    pos: float
    kind: str  # "road" | "pedestrian"
    segments: list  # [(a, b)] spans along the street that exist (between nodes / edges)


@dataclass
class Block:
    rect: tuple  # x0, x1, y0, y1 (world)
    edge: dict  # side ("s", "e", "n", "w") -> True when it lies on the district edge
    kind: str = ""


@dataclass
class Plan:
    W: float
    H: float
    streets: list
    blocks: list
    nodes: np.ndarray  # [N, 2]
    edges: list  # [(i, j, kind)]


def _positions(rng, length: float, n: int) -> list[float]:
    """`n` street centre lines along `length`, every block between them at least MIN_BLOCK deep."""
    free = length - n * CORRIDOR - (n + 1) * MIN_BLOCK
    cuts = np.sort(rng.uniform(0, free, n))
    return [float(MIN_BLOCK * (k + 1) + CORRIDOR * k + cuts[k] + CORRIDOR / 2) for k in range(n)]


def plan_streets(rng: np.random.Generator) -> Plan:
    """Extent, street network and blocks of one district."""
    while True:
        W, H = float(rng.uniform(88.0, 112.0)), float(rng.uniform(62.0, 86.0))
        if 5000.0 <= W * H <= 10000.0:
            break
    nv_max = int((W - MIN_BLOCK) // (CORRIDOR + MIN_BLOCK))
    nh_max = int((H - MIN_BLOCK) // (CORRIDOR + MIN_BLOCK))
    nv, nh = int(rng.integers(1, nv_max + 1)), int(rng.integers(1, nh_max + 1))
    xs, ys = _positions(rng, W, nv), _positions(rng, H, nh)
    xb = [0.0] + [v for x in xs for v in (x - CORRIDOR / 2, x + CORRIDOR / 2)] + [W]  # cell bounds
    yb = [0.0] + [v for y in ys for v in (y - CORRIDOR / 2, y + CORRIDOR / 2)] + [H]
    ynodes, xnodes = [0.0] + ys + [H], [0.0] + xs + [W]
    streets = [Street("v", x, "road", [(ynodes[j], ynodes[j + 1]) for j in range(nh + 1)]) for x in xs]
    streets += [Street("h", y, "road", [(xnodes[i], xnodes[i + 1]) for i in range(nv + 1)]) for y in ys]
    if len(streets) > 2 and rng.random() < 0.3:
        streets[int(rng.integers(len(streets)))].kind = "pedestrian"
    # segments removed along one axis only, so merged cells stay rectangles
    cells = (nv + 1) * (nh + 1)
    parent = list(range(cells))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    axis = "v" if rng.random() < 0.5 else "h"
    cand = [(si, k) for si, s in enumerate(streets) if s.axis == axis for k in range(len(s.segments))]
    n_remove = min(int(rng.integers(0, 3)), max(cells - 3, 0))
    for pick in rng.permutation(len(cand))[:n_remove]:
        si, k = cand[pick]
        s = streets[si]
        if len(s.segments) <= 1:
            continue
        idx = [i for i, x in enumerate(xs) if x == s.pos] if s.axis == "v" else [j for j, y in enumerate(ys) if y == s.pos]
        i = idx[0]
        a, b = ((k * (nv + 1) + i), (k * (nv + 1) + i + 1)) if s.axis == "v" else ((i * (nv + 1) + k), ((i + 1) * (nv + 1) + k))
        parent[find(a)] = find(b)
        s.segments = [seg for kk, seg in enumerate(s.segments) if kk != k]
    groups: dict[int, list[int]] = {}
    for c in range(cells):
        groups.setdefault(find(c), []).append(c)
    blocks = []
    for members in groups.values():
        ii = [c % (nv + 1) for c in members]
        jj = [c // (nv + 1) for c in members]
        x0, x1 = xb[2 * min(ii)], xb[2 * max(ii) + 1]
        y0, y1 = yb[2 * min(jj)], yb[2 * max(jj) + 1]
        blocks.append(Block((x0, x1, y0, y1), {"s": y0 == 0.0, "n": y1 == H, "w": x0 == 0.0, "e": x1 == W}))
    blocks.sort(key=lambda bl: (bl.rect[2], bl.rect[0]))
    # the street graph: junctions and street ends as nodes, present segments as edges
    pts: dict[tuple, int] = {}

    def node(p):
        key = (round(p[0], 3), round(p[1], 3))
        return pts.setdefault(key, len(pts))

    edges = []
    for s in streets:
        for a, b in s.segments:
            p, q = ((s.pos, a), (s.pos, b)) if s.axis == "v" else ((a, s.pos), (b, s.pos))
            edges.append((node(p), node(q), s.kind))
    return Plan(W, H, streets, blocks, np.array(list(pts), np.float64), edges)


def _street_rects(plan: Plan) -> list:
    """Ground rectangles of roads, pedestrian streets, sidewalks and crossings (world frame)."""
    rects = []
    for s in plan.streets:
        for a, b in s.segments:
            def r(half, lo=a, hi=b):
                return (s.pos - half, s.pos + half, lo, hi) if s.axis == "v" else (lo, hi, s.pos - half, s.pos + half)
            rects.append((*r(CORRIDOR / 2), 1, "paving", BASE))
            if s.kind == "road":
                rects.append((*r(ROAD_W / 2), 3, "road", 0.0))
            else:
                rects.append((*r(ROAD_W / 2), 2, "plaza_stone", BASE))
    # zebra crossings on every road arm of every junction (not at the district edge)
    junctions = [tuple(p) for p in plan.nodes if 0.0 < p[0] < plan.W and 0.0 < p[1] < plan.H]
    for s in plan.streets:
        if s.kind != "road":
            continue
        for a, b in s.segments:
            for end, sign in ((a, 1.0), (b, -1.0)):
                p = (s.pos, end) if s.axis == "v" else (end, s.pos)
                if p not in junctions:
                    continue
                lo = end + sign * (CORRIDOR / 2 + 0.6)
                hi = lo + sign * 3.0
                lo, hi = min(lo, hi), max(lo, hi)
                for k in range(int(ROAD_W // 1.0)):
                    c0 = s.pos - ROAD_W / 2 + 0.35 + k * 1.0
                    stripe = (c0, c0 + 0.5, lo, hi) if s.axis == "v" else (lo, hi, c0, c0 + 0.5)
                    rects.append((*stripe, 4, "marking", 0.0))
    return rects


def _kerbs(b: Builder, winner, xs, ys, rects) -> None:
    """Vertical kerb faces wherever a road cell meets a raised one, facing the road."""
    low = np.array([rects[k][6] == 0.0 if k >= 0 else False for k in winner.ravel()]).reshape(winner.shape)
    # x-neighbours
    ny, nx = low.shape
    for j in range(ny):
        for i in range(nx - 1):
            if low[j, i] != low[j, i + 1]:
                b.vquad_x(xs[i + 1], ys[j], ys[j + 1], 0.0, BASE, M["granite"], +1 if low[j, i + 1] else -1)
    for j in range(ny - 1):
        for i in range(nx):
            if low[j, i] != low[j + 1, i]:
                b.vquad_y(ys[j + 1], xs[i], xs[i + 1], 0.0, BASE, M["granite"], +1 if low[j + 1, i] else -1)


# --------------------------------------------------------------------------- blocks (local frame)


def _block_frame(block: Block, front: str) -> tuple[Frame, float, float, dict]:
    """Frame with the block's `front` side at local y = 0; local (w, d) and which local sides are on the edge."""
    x0, x1, y0, y1 = block.rect
    if front == "s":
        f, w, d, order = Frame(x0, y0, 0), x1 - x0, y1 - y0, ("s", "e", "n", "w")
    elif front == "e":
        f, w, d, order = Frame(x1, y0, 1), y1 - y0, x1 - x0, ("e", "n", "w", "s")
    elif front == "n":
        f, w, d, order = Frame(x1, y1, 2), x1 - x0, y1 - y0, ("n", "w", "s", "e")
    else:
        f, w, d, order = Frame(x0, y1, 3), y1 - y0, x1 - x0, ("w", "s", "e", "n")
    # local sides: front (y = 0), right (x = w), back (y = d), left (x = 0)
    edge = {"front": block.edge[order[0]], "right": block.edge[order[1]], "back": block.edge[order[2]],
            "left": block.edge[order[3]]}
    return f, w, d, edge


def _loop_rect(w, d, edge) -> tuple:
    """The block loop (local): LOOP_OFFSET outside a street side, inside along the district edge."""
    o = {k: (LOOP_OFFSET if v else -LOOP_OFFSET) for k, v in edge.items()}
    return (o["left"], w - o["right"], o["front"], d - o["back"])


def _margins(edge, street: float) -> dict:
    return {k: (EDGE_MARGIN if v else street) for k, v in edge.items()}


class _Clear:
    """Keeps furniture off the capture paths: points closer than `r` to a path segment are refused."""

    def __init__(self, polylines):
        segs = []
        for pl in polylines:
            p = np.asarray(pl, np.float64)
            segs += [(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]
        self.a = np.array([s[0] for s in segs])
        self.b = np.array([s[1] for s in segs])

    def __call__(self, x, y, r) -> bool:
        p = np.array([x, y])
        ab = self.b - self.a
        t = np.clip(((p - self.a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        d = np.linalg.norm(self.a + t[:, None] * ab - p, axis=1)
        return bool(d.min() > r)


def _scatter(rng, clear, zone, n, r, tries=40, taken=None, avoid=()):
    """Up to `n` points in the rectangle `zone` at least `r` from every path and from each other, outside the
    rectangles `avoid`."""
    taken = [] if taken is None else taken
    out = []
    x0, x1, y0, y1 = zone
    if x1 <= x0 or y1 <= y0:
        return out
    for _ in range(n * tries):
        if len(out) >= n:
            break
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        if any(a[0] - r <= x <= a[1] + r and a[2] - r <= y <= a[3] + r for a in avoid):
            continue
        if clear(x, y, r) and all((x - a) ** 2 + (y - c) ** 2 > (2 * r) ** 2 for a, c in taken + out):
            out.append((x, y))
    taken += out
    return out


@dataclass
class BlockResult:
    paths: list = field(default_factory=list)  # local polylines (closed loops)
    indoor: list = field(default_factory=list)  # local (x0, x1, y0, y1, z_min, z_max)
    kind: str = ""


def _building_shell(b: Builder, fp, z0, top, storeys_mat="facade"):
    """A closed building: one box, every face but its bottom."""
    x0, x1, y0, y1 = fp
    b.box((x0, y0, z0), (x1, y1, top), M[storeys_mat], mats={"+z": M["concrete"]})


def _forecourt(b: Builder, w, d, holes, material="paving"):
    rects = [(0.0, w, 0.0, d, 1, material, BASE)] + [(*h, 5, None, BASE) for h in holes]
    emit_cells(b, rects, (0.0, w, 0.0, d))


def _enterable(b: Builder, hf: HeightField, fr: Frame, w, d, edge, rng, clear_outer) -> BlockResult:
    m = _margins(edge, float(rng.uniform(2.5, 4.0)))
    variant = ["lobby", "hall", "arcade"][int(rng.integers(3))]
    front_m = 5.0 if variant == "arcade" else float(rng.uniform(3.0, 5.0))
    bx0, bx1 = m["left"], w - m["right"]
    by0, by1 = front_m, d - m["back"]
    bx1 = min(bx1, bx0 + 30.0)
    by1 = min(by1, by0 + 24.0)
    ceiling = BASE + (6.0 if variant == "hall" else 4.0)
    top = ceiling + float(rng.uniform(4.0, 16.0))
    ix0, ix1, iy0, iy1 = bx0 + WALL_T, bx1 - WALL_T, by0 + WALL_T, by1 - WALL_T
    ax = float(rng.uniform(ix0 + 3.0, ix1 - 5.4))
    door_a = (ax, ax + 2.4)
    side = ["left", "right", "back"][int(rng.integers(3))]
    # the rig's walk: in through the front door, round the room 2 m inside its walls, out the same door
    cx = ax + 1.2
    inner = (ix0 + 2.0, ix1 - 2.0, iy0 + 2.0, iy1 - 2.0)
    path = [(cx, -LOOP_OFFSET), (cx, inner[2]), (inner[0], inner[2]), (inner[0], inner[3]), (inner[1], inner[3]),
            (inner[1], inner[2]), (cx, inner[2])]
    clear = _Clear([path, *clear_outer])
    # floor: forecourt paving around, lobby floor inside
    _forecourt(b, w, d, [(bx0, bx1, by0, by1)])
    b.rect(bx0, bx1, by0, by1, BASE, M["lobby_floor"])
    z0 = BASE
    if side == "back":
        bd = float(rng.uniform(ix0 + 2.0, ix1 - 4.4))
        wall_x(b, bx0, bx1, by1 - WALL_T, by1, z0, ceiling, [(bd, bd + 2.4)], M["brick"], M["plaster"], "-y")
    else:
        wall_x(b, bx0, bx1, by1 - WALL_T, by1, z0, ceiling, [], M["brick"], M["plaster"], "-y")
    wall_x(b, bx0, bx1, by0, by0 + WALL_T, z0, ceiling, [door_a], M["brick"], M["plaster"], "+y")
    sd = float(rng.uniform(iy0 + 2.0, iy1 - 4.4))
    wall_y(b, bx0, bx0 + WALL_T, iy0, iy1, z0, ceiling, [(sd, sd + 2.4)] if side == "left" else [], M["brick"],
           M["plaster"], "+x")
    wall_y(b, bx1 - WALL_T, bx1, iy0, iy1, z0, ceiling, [(sd, sd + 2.4)] if side == "right" else [], M["brick"],
           M["plaster"], "-x")
    # pillars on a grid in the middle of the room, off the walk
    pitch = 6.0 if variant == "hall" else 5.0
    for px in np.arange(ix0 + 4.0, ix1 - 3.9, pitch):
        for py in np.arange(iy0 + 4.0, iy1 - 3.9, pitch):
            if clear(px, py, 1.0):
                b.box((px - 0.25, py - 0.25, z0), (px + 0.25, py + 0.25, ceiling), M["concrete"], skip=("-z", "+z"))
    if variant != "hall":
        dx, dy = 0.5 * (ix0 + ix1), iy1 - 4.5
        if clear(dx, dy, 2.4):
            b.box((dx - 2.0, dy - 0.4, z0), (dx + 2.0, dy + 0.4, z0 + 1.05), M["wood"])
    # the storeys above (over the arcade too), the arcade's pillars
    fy0 = by0 - (3.0 if variant == "arcade" else 0.0)
    b.box((bx0, fy0, ceiling), (bx1, by1, top), M["facade"], mats={"-z": M["ceiling"], "+z": M["concrete"]}, skip=())
    if variant == "arcade":
        for px in np.arange(bx0 + 0.3, bx1 - 0.2, 4.0):
            if abs(px - cx) > 1.8:
                b.box((px - 0.2, fy0, z0), (px + 0.2, fy0 + 0.4, ceiling), M["concrete"], skip=("-z", "+z"))
    taken = []
    for x, y in _scatter(rng, clear, (0.8, w - 0.8, 0.8, by0 - 0.8), 3, 1.0, taken=taken):
        planter(b, x, y, BASE, rng)
    return BlockResult([path], [(ix0, ix1, iy0, iy1, BASE - 0.5, ceiling + 0.01)], f"building_{variant}")


def _ramp(b: Builder, hf: HeightField, fr: Frame, x0, x1, y0, y1, z0, z1):
    """Ramp rising along +y from z0 at y0 to z1 at y1, with its two side faces."""
    b.poly([[x0, y0, z0], [x1, y0, z0], [x1, y1, z1], [x0, y1, z1]], [0, -(z1 - z0), y1 - y0], M["concrete"])
    for xs, sgn in ((x0, -1), (x1, +1)):
        b.poly([[xs, y0, z0], [xs, y1, z0], [xs, y1, z1]], [sgn, 0, 0], M["concrete"])
    hf.paint(fr, x0, x1, y0, y1, lambda lx, ly: z0 + (ly - y0) / (y1 - y0) * (z1 - z0))


def _stairs(b: Builder, hf: HeightField, fr: Frame, x0, x1, y_top, z0, z1) -> float:
    """Stairs climbing along +y to the edge y_top (height z1) from z0; returns the y of the bottom riser."""
    n = int(np.ceil((z1 - z0) / MAX_RISE - 1e-9))
    rise = (z1 - z0) / n
    y_bot = y_top - (n - 1) * TREAD
    for k in range(1, n + 1):
        y_r = y_bot + (k - 1) * TREAD
        lo, hi = z0 + (k - 1) * rise, z0 + k * rise
        b.vquad_y(y_r, x0, x1, lo, hi, M["concrete"], -1)
        if k < n:
            b.rect(x0, x1, y_r, y_r + TREAD, hi, M["concrete"])
            for xs, sgn in ((x0, -1), (x1, +1)):
                b.vquad_x(xs, y_r, y_r + TREAD, z0, hi, M["concrete"], sgn)
            hf.paint(fr, x0, x1, y_r, y_r + TREAD, lambda lx, ly, h=hi: np.full_like(lx, h))
    return y_bot


def _terrace(b: Builder, hf, fr, rect, z0, z1, openings, top_rects):
    """A raised level over `rect` at z1 above the surrounding z0: its top (`top_rects`: ground rectangles at z1)
    and retaining faces, the front one left open over the x ranges `openings` (ramps and stairs)."""
    x0, x1, y0, y1 = rect
    emit_cells(b, [(*r[:4], r[4], r[5], z1) for r in top_rects], rect)
    hf.paint(fr, x0, x1, y0, y1, lambda lx, ly: np.full_like(lx, z1))
    edges = [x0] + [v for o in sorted(openings) for v in o] + [x1]
    for a, c in zip(edges[0::2], edges[1::2]):
        if c - a > 1e-6:
            b.vquad_y(y0, a, c, z0, z1, M["concrete"], -1)
    b.vquad_y(y1, x0, x1, z0, z1, M["concrete"], +1)
    b.vquad_x(x0, y0, y1, z0, z1, M["concrete"], -1)
    b.vquad_x(x1, y0, y1, z0, z1, M["concrete"], +1)


def _plaza(b: Builder, hf, fr, w, d, edge, rng, clear_outer) -> BlockResult | None:
    m = _margins(edge, 1.5)
    h1 = float(rng.uniform(0.6, 2.0))
    room = d - m["back"] - 8.0 - 1.5  # the front strip holds the ramp; the terrace keeps >= 8 m
    h1 = min(h1, RAMP_TAN * room)
    if h1 < 0.5 or w - m["left"] - m["right"] < 14.0:
        return None
    L1 = h1 / RAMP_TAN
    f = L1 + 1.5
    t1 = (m["left"], w - m["right"], f, d - m["back"])
    z1 = BASE + h1
    xr, xs = t1[0], t1[1] - 4.0
    ramp1 = (xr, xs - 1.0)
    stairs1 = (xs, xs + 3.0)
    # an upper tier when the terrace is deep enough
    L2 = 0.0
    two = False
    if rng.random() < 0.6:
        h2 = float(rng.uniform(0.8, 1.8))
        L2 = h2 / RAMP_TAN
        two = (t1[3] - t1[2]) - (2.0 + L2) >= 7.0 and (t1[1] - t1[0]) >= 20.0
    path = [(xr + 2.0, -LOOP_OFFSET), (xr + 2.0, f + 1.5)]
    top_rects = [(*t1, 1, "plaza_stone")]
    if two:
        z2 = z1 + h2
        t2 = (t1[0] + 3.0, t1[1] - 3.0, f + 2.0 + L2, t1[3] - 2.0)
        xr2, xs2 = t2[0], t2[1] - 4.0
        top_rects.append((*t2, 3, None))
        path += [(xr2 + 2.0, f + 1.5), (xr2 + 2.0, t2[2] + 1.5), (xs2 + 1.5, t2[2] + 1.5), (xs2 + 1.5, f + 1.5)]
    path += [(xs + 1.5, f + 1.5), (xs + 1.5, -LOOP_OFFSET)]
    clear = _Clear([path, *clear_outer])
    lawn = (t1[0] + 1.0, t1[0] + 1.0 + min(10.0, 0.4 * (t1[1] - t1[0])), t1[3] - 5.0, t1[3] - 1.0)
    if not two and lawn[3] > t1[2] + 1.0:
        top_rects.append((*lawn, 2, "grass"))
    _forecourt(b, w, d, [t1])
    _terrace(b, hf, fr, t1, BASE, z1, [ramp1, stairs1], top_rects)
    _ramp(b, hf, fr, *ramp1, f - L1, f, BASE, z1)
    _stairs(b, hf, fr, *stairs1, f, BASE, z1)
    level = [(t1, z1)]
    if two:
        _terrace(b, hf, fr, t2, z1, z2, [(xr2, xs2 - 1.0), (xs2, xs2 + 3.0)],
                 [(*t2, 1, "plaza_stone"), (t2[0] + 1.0, t2[0] + 7.0, t2[3] - 5.0, t2[3] - 1.0, 2, "grass")])
        _ramp(b, hf, fr, xr2, xs2 - 1.0, t2[2] - L2, t2[2], z1, z2)
        _stairs(b, hf, fr, xs2, xs2 + 3.0, t2[2], z1, z2)
        level.append((t2, z2))
    taken = []
    for li, (rect, z) in enumerate(level):
        zone = (rect[0] + 1.0, rect[1] - 1.0, rect[2] + 1.0, rect[3] - 1.0)
        avoid = [level[li + 1][0]] if li + 1 < len(level) else []
        for x, y in _scatter(rng, clear, zone, 2, 2.2, taken=taken, avoid=avoid):
            tree(b, rng, x, y, z)
        for x, y in _scatter(rng, clear, zone, 2, 1.1, taken=taken, avoid=avoid):
            planter(b, x, y, z, rng)
        for x, y in _scatter(rng, clear, zone, 2, 1.3, taken=taken, avoid=avoid):
            bench(b, x, y, z, bool(rng.random() < 0.5))
    return BlockResult([path], [], "plaza_two_tier" if two else "plaza")


def _park(b: Builder, hf, fr, w, d, edge, rng, clear_outer) -> BlockResult:
    m = _margins(edge, 0.0)
    inset = {k: v + float(rng.uniform(3.5, 6.0)) for k, v in m.items()}
    r0, r1, q0, q1 = inset["left"], w - inset["right"], inset["front"], d - inset["back"]
    xe = float(rng.uniform(r0 + 2.0, r1 - 2.0))
    half = 1.2
    rects = [(0.0, w, 0.0, d, 1, "grass", BASE)]
    for x0, x1, y0, y1 in ((r0 - half, r1 + half, q0 - half, q0 + half), (r0 - half, r1 + half, q1 - half, q1 + half),
                           (r0 - half, r0 + half, q0, q1), (r1 - half, r1 + half, q0, q1), (xe - half, xe + half, 0.0, q0)):
        rects.append((x0, x1, y0, y1, 2, "paving", BASE))
    for side, rect in (("back", (0.0, w, d - m["back"], d)), ("left", (0.0, m["left"], 0.0, d)),
                       ("right", (w - m["right"], w, 0.0, d))):
        if edge[side]:
            rects.append((*rect, 2, "paving", BASE))
    path = [(xe, -LOOP_OFFSET), (xe, q0), (r0, q0), (r0, q1), (r1, q1), (r1, q0), (xe, q0)]
    clear = _Clear([path, *clear_outer])
    trees = _scatter(rng, clear, (1.0, w - 1.0, 1.0, d - 1.0), int(rng.integers(6, 14)), 2.3)
    pits = [(x - 0.7, x + 0.7, y - 0.7, y + 0.7, 5, None, BASE) for x, y in trees]
    emit_cells(b, rects + pits, (0.0, w, 0.0, d))
    for x, y in trees:
        tree(b, rng, x, y, BASE)
    taken = list(trees)
    for x, y in _scatter(rng, clear, (r0 + 2.0, r1 - 2.0, q0 + 2.0, q1 - 2.0), 3, 1.3, taken=taken):
        bench(b, x, y, BASE, bool(rng.random() < 0.5))
    for x, y in _scatter(rng, clear, (1.0, w - 1.0, 1.0, d - 1.0), 3, 0.8, taken=taken):
        pole(b, x, y, BASE, 4.5)
    return BlockResult([path], [], "park")


def _closed(b: Builder, hf, fr, w, d, edge, rng, clear_outer) -> BlockResult:
    m = _margins(edge, float(rng.uniform(1.0, 4.0)))
    front = float(rng.uniform(3.0, 6.0))
    fp = (m["left"], w - m["right"], front, d - m["back"])
    _forecourt(b, w, d, [fp])
    _building_shell(b, fp, BASE, BASE + float(rng.uniform(8.0, 22.0)), "facade" if rng.random() < 0.7 else "brick")
    clear = _Clear(list(clear_outer))
    taken = []
    for x, y in _scatter(rng, clear, (0.8, w - 0.8, 0.8, front - 0.8), 3, 1.1, taken=taken):
        planter(b, x, y, BASE, rng) if rng.random() < 0.6 else bench(b, x, y, BASE, True)
    return BlockResult([], [], "building_closed")


KINDS = {"enterable": _enterable, "plaza": _plaza, "park": _park, "closed": _closed}


# --------------------------------------------------------------------------- street furniture, edge, assembly


def _sidewalk_furniture(b: Builder, plan: Plan, rng) -> None:
    junctions = plan.nodes
    for s in plan.streets:
        spacing = float(rng.uniform(8.0, 12.0))
        for a, c in s.segments:
            for side in (-1.0, 1.0):
                off = s.pos + side * (ROAD_W / 2 + 0.9)
                for t in np.arange(a + spacing / 2, c, spacing):
                    p = (off, t) if s.axis == "v" else (t, off)
                    if np.min(np.abs(junctions - np.array(p)).max(1)) < CORRIDOR / 2 + 4.5:
                        continue
                    if s.kind == "road":
                        tree(b, rng, p[0], p[1], BASE)
                    else:
                        planter(b, p[0], p[1], BASE, rng)
                off = s.pos + side * (ROAD_W / 2 + 0.35)
                for t in np.arange(a + spacing, c, 2 * spacing):
                    p = (off, t) if s.axis == "v" else (t, off)
                    if np.min(np.abs(junctions - np.array(p)).max(1)) >= CORRIDOR / 2 + 4.5:
                        pole(b, p[0], p[1], BASE)


def _parked_cars(b: Builder, plan: Plan, rng) -> int:
    """Cars along the kerbs of road segments, away from the junctions and crossings. -> how many."""
    n = 0
    for s in plan.streets:
        if s.kind != "road":
            continue
        for a, c in s.segments:
            for side in (-1.0, 1.0):
                off = s.pos + side * (ROAD_W / 2 - 1.1)
                t = a + CORRIDOR / 2 + 5.0
                while t + 4.4 < c - CORRIDOR / 2 - 5.0:
                    if rng.random() < 0.45:
                        sub = Builder()
                        car(sub, 0.0, 4.4, 0.0, 0.0)
                        if rng.random() < 0.5:  # a light-coloured car
                            sub.m = [np.where(m_ == M["car_paint"], M["car_paint_light"], m_).astype(np.int16)
                                     for m_ in sub.m]
                        # along x for an "h" street, along y (a quarter turn) for a "v" street
                        fr = Frame(t, off, 0) if s.axis == "h" else Frame(off, t, 1)
                        fr.place(b, sub)
                        n += 1
                    t += 6.0
    return n


def _edge_walls(b: Builder, plan: Plan, rng) -> None:
    """Facades closing the district on its four sides, facing in."""
    W, H = plan.W, plan.H
    hs = rng.uniform(10.0, 18.0, 4)
    b.box((-1.0, -1.0, 0.0), (W + 1.0, 0.0, hs[0]), M["facade"], skip=("-z", "+z", "-y", "-x", "+x"))
    b.box((-1.0, H, 0.0), (W + 1.0, H + 1.0, hs[1]), M["facade"], skip=("-z", "+z", "+y", "-x", "+x"))
    b.box((-1.0, 0.0, 0.0), (0.0, H, hs[2]), M["facade"], skip=("-z", "+z", "-x", "-y", "+y"))
    b.box((W, 0.0, 0.0), (W + 1.0, H, hs[3]), M["facade"], skip=("-z", "+z", "+x", "-y", "+y"))


def _assign_kinds(plan: Plan, rng) -> list[str]:
    """One block kind each; the three walkable kinds first, on blocks that fit them."""
    n = len(plan.blocks)
    order = list(rng.permutation(n))
    depth = [min(b.rect[1] - b.rect[0], b.rect[3] - b.rect[2]) for b in plan.blocks]
    kinds = [""] * n
    big = max(order, key=lambda i: depth[i])  # the plaza needs room for its ramp
    kinds[big] = "plaza"
    rest = [i for i in order if i != big]
    for i, k in zip(rest, ("enterable", "park")):
        kinds[i] = k
    for i in rest[2:]:
        kinds[i] = ["closed", "closed", "enterable", "park", "plaza"][int(rng.integers(5))]
    return kinds


def _front_side(block: Block, rng) -> str:
    streets = [s for s in ("s", "e", "n", "w") if not block.edge[s]]
    return streets[int(rng.integers(len(streets)))]


@dataclass
class District:
    layout: Layout
    paths: tuple  # CapturePath, world frame
    plan: Plan
    block_kinds: list
    cars: int


def build_district(seed: int) -> District:
    """The district for `seed`: geometry, capture paths and its street plan."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 4711]))
    plan = plan_streets(rng)
    hf = HeightField(plan.W, plan.H)
    b = Builder()
    rects = _street_rects(plan)
    winner, xs, ys = emit_cells(b, rects, (0.0, plan.W, 0.0, plan.H))
    for r in rects:
        if r[6] == 0.0:
            hf.paint(WORLD, r[0], r[1], r[2], r[3], lambda lx, ly: np.zeros_like(lx))
    _kerbs(b, winner, xs, ys, rects)
    kinds = _assign_kinds(plan, rng)
    paths, regions, realised = [], [], []
    for bi, (block, kind) in enumerate(zip(plan.blocks, kinds)):
        fr, w, d, edge = _block_frame(block, _front_side(block, rng))
        lx0, lx1, ly0, ly1 = _loop_rect(w, d, edge)
        loop = [(lx0, ly0), (lx1, ly0), (lx1, ly1), (lx0, ly1)]
        sub = Builder()
        res = KINDS[kind](sub, hf, fr, w, d, edge, rng, [loop])
        if res is None:  # the block cannot hold the plaza: a park instead
            sub = Builder()
            res = _park(sub, hf, fr, w, d, edge, rng, [loop])
        fr.place(b, sub)
        realised.append(res.kind)
        paths.append(CapturePath(f"block{bi}_loop", "train", tuple(map(tuple, np.round(fr.xy(loop), 4))), True))
        for k, pl in enumerate(res.paths):
            paths.append(CapturePath(f"block{bi}_{res.kind}_{k}", "train", tuple(map(tuple, np.round(fr.xy(pl), 4))),
                                     True))
        for x0, x1, y0, y1, z0, z1 in res.indoor:
            X0, X1, Y0, Y1 = fr.rect(x0, x1, y0, y1)
            e = 0.01
            regions.append({"polygon_xy": [[X0 - e, Y0 - e], [X1 + e, Y0 - e], [X1 + e, Y1 + e], [X0 - e, Y1 + e]],
                            "z_min": z0, "z_max": z1})
    _sidewalk_furniture(b, plan, rng)
    cars = _parked_cars(b, plan, rng)
    _edge_walls(b, plan, rng)
    for si, s in enumerate(plan.streets):
        for k, (a, c) in enumerate(s.segments):
            a_, c_ = a + 2.0, c - 2.0
            wp = ((s.pos, a_), (s.pos, c_)) if s.axis == "v" else ((a_, s.pos), (c_, s.pos))
            paths.append(CapturePath(f"street{si}_{k}", "val", wp, False))
    V, F, Mt = b.build()
    palette = np.array([[0.62, 0.08, 0.07], [0.08, 0.22, 0.55], [0.15, 0.35, 0.2], [0.55, 0.45, 0.1]])
    layout = Layout(V, F, Mt, palette[int(rng.integers(len(palette)))], regions, hf)
    return District(layout, tuple(paths), plan, realised, cars)
