"""The district's block kinds, each built once in its own frame (the block spans [0, w] x [0, d], its front on a
street at y = 0): an enterable building, a plaza on terraces with ramps and stairs, a park, a closed building
(`KINDS`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..demo.layout import Builder, M, bench, planter, pole, tree, wall_x, wall_y

from .frames import (BASE, EDGE_MARGIN, LOOP_OFFSET, MAX_RISE, RAMP_TAN, TREAD, WALL_T, Block, Frame, HeightField,
                     emit_cells)



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
