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

from dataclasses import dataclass

import numpy as np

from ..demo.capture import CapturePath
from ..demo.layout import Builder, Layout, M, car, planter, pole, tree

from .blocks import KINDS, _block_frame, _loop_rect, _park
from .frames import BASE, CORRIDOR, MIN_BLOCK, ROAD_W, WORLD, Block, Frame, HeightField, Plan, Street, emit_cells



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
