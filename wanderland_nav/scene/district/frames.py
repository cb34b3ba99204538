"""The district's shared pieces: its dimensions, block frames (quarter turns into place), the walked-surface
height field, and the street plan's records (`Street`, `Block`, `Plan`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..demo.layout import Builder, M

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
