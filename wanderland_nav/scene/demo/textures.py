"""Procedural, world-space textures of the demo scene (no UV maps, no image files).

Every surface point is coloured by a function of its material, its nav-frame position and
its normal: the 2D texture coordinates are the two world axes spanning the face's dominant
plane. Fine patterns (mortar, grout, lane markings, speckle) are band-limited by the pixel
*footprint* `fw` (metres covered by one sample): a line narrower than the footprint fades to its
mean coverage and noise octaves finer than it are dropped. So a 256 px view, a LiDAR return and
a splat covering 8 cm all see the same local average colour, which keeps the photometric
comparison between the ray-cast images and the splat renders meaningful.

Shading is view-independent (ambient + a fixed sun on the outward normal, a dimmer constant
light inside the lobby) so that SH-0 splats can reproduce it exactly.
All functions are batched over points: `[N]`/`[N, 3]` numpy arrays, float64 inside.
"""

from __future__ import annotations

import numpy as np

MATERIALS = (
    "asphalt", "granite", "paving", "plaza_stone", "concrete", "brick", "facade", "lobby_floor", "plaster",
    "ceiling", "wood", "metal", "bark", "foliage", "terracotta", "soil", "car_paint", "glass", "rubber", "grass",
    "road", "marking", "car_paint_light",
)
SUN = np.array([0.3, 0.5, 0.81]) / np.linalg.norm([0.3, 0.5, 0.81])
AMBIENT, DIFFUSE, INDOOR_LIGHT = 0.62, 0.45, 0.78
SKY_HORIZON = np.array([0.86, 0.9, 0.95])
SKY_ZENITH = np.array([0.42, 0.6, 0.86])

_M1, _M2, _M3 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def hash01(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Deterministic hash of integer lattice coordinates `[N]` -> float64 in [0, 1) (splitmix64)."""
    with np.errstate(over="ignore"):
        h = ix.astype(np.int64).astype(np.uint64) * _M1
        h ^= iy.astype(np.int64).astype(np.uint64) * _M2 + np.uint64(seed & 0xFFFFFFFF) * _M3
        h ^= h >> np.uint64(30)
        h *= _M2
        h ^= h >> np.uint64(27)
        h *= _M3
        h ^= h >> np.uint64(31)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def value_noise(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """Smooth value noise with unit lattice spacing, values in [0, 1]."""
    iu, iv = np.floor(u), np.floor(v)
    fu, fv = u - iu, v - iv
    su, sv = fu * fu * (3 - 2 * fu), fv * fv * (3 - 2 * fv)
    iu, iv = iu.astype(np.int64), iv.astype(np.int64)
    a, b = hash01(iu, iv, seed), hash01(iu + 1, iv, seed)
    c, d = hash01(iu, iv + 1, seed), hash01(iu + 1, iv + 1, seed)
    return (a * (1 - su) + b * su) * (1 - sv) + (c * (1 - su) + d * su) * sv


def fbm(u, v, freq: float, octaves: int, seed: int, fw: np.ndarray) -> np.ndarray:
    """Band-limited fractal noise in about [-0.5, 0.5]: octaves finer than the footprint fade out."""
    out = np.zeros_like(u)
    amp, f = 0.5, freq
    for o in range(octaves):
        w = np.clip(1.5 - 2.0 * f * fw, 0.0, 1.0)  # 1 while the period is > 2 footprints
        if not np.any(w > 0):
            break
        out += amp * w * (value_noise(u * f, v * f, seed + 101 * o) - 0.5)
        amp *= 0.5
        f *= 2.0
    return out


def lines(c: np.ndarray, period: float, width: float, fw: np.ndarray, offset: float = 0.0) -> np.ndarray:
    """Coverage in [0, 1] of lines of `width` every `period` along coordinate `c`, antialiased by `fw`."""
    d = np.abs(np.mod(c - offset + 0.5 * period, period) - 0.5 * period)  # distance to the nearest line centre
    sharp = np.clip((0.5 * width - d) / np.maximum(fw, 1e-4) + 0.5, 0.0, 1.0)
    a = np.clip((fw - 0.25 * period) / (0.5 * period), 0.0, 1.0)  # footprint ~ period: use the mean
    return (1 - a) * sharp + a * min(width / period, 1.0)


def box_mask(u, v, u0, u1, v0, v1, fw):
    """Antialiased indicator of the rectangle [u0, u1] x [v0, v1]."""
    e = np.maximum(fw, 1e-4)
    return (np.clip((u - u0) / e + 0.5, 0, 1) * np.clip((u1 - u) / e + 0.5, 0, 1)
            * np.clip((v - v0) / e + 0.5, 0, 1) * np.clip((v1 - v) / e + 0.5, 0, 1))


def _mix(a, b, t):
    t = np.asarray(t)[..., None]
    return np.asarray(a) * (1 - t) + np.asarray(b) * t


def _tiles(u, v, tu, tv, joint, fw, seed, bond: bool):
    """Per-tile random value and joint coverage for a tiling of `tu x tv` tiles (running bond optional)."""
    row = np.floor(v / tv)
    uu = u + (np.mod(row, 2) * 0.5 * tu if bond else 0.0)
    col = np.floor(uu / tu)
    rnd = hash01(col.astype(np.int64), row.astype(np.int64), seed)
    j = np.maximum(lines(uu, tu, joint, fw), lines(v, tv, joint, fw))
    return rnd, j


def _coords(p: np.ndarray, n: np.ndarray):
    """Texture coordinates (u, v) spanning the dominant plane of each normal, and a 'vertical' flag."""
    ax = np.abs(n).argmax(1)
    u = np.where(ax == 0, p[:, 1], p[:, 0])
    v = np.where(ax == 2, p[:, 1], p[:, 2])
    return u, v, ax != 2


def albedo(material: np.ndarray, p: np.ndarray, n: np.ndarray, fw: np.ndarray, seed: int,
           car_color=(0.62, 0.08, 0.07)) -> np.ndarray:
    """Surface albedo `[N, 3]` in [0, 1] for `material [N]` (index into MATERIALS) at points `p [N, 3]`
    with outward normals `n [N, 3]` and sample footprints `fw [N]` (metres)."""
    N = material.shape[0]
    out = np.zeros((N, 3))
    u_all, v_all, vert_all = _coords(p, n)
    for mid in np.unique(material):
        sel = np.flatnonzero(material == mid)
        name = MATERIALS[int(mid)]
        at = (u_all[sel], v_all[sel], fw[sel], p[sel], vert_all[sel], seed * 1000 + int(mid) * 17)
        col = _ground_and_wall_albedo(name, *at)
        out[sel] = col if col is not None else _object_albedo(name, *at, car_color)
    return np.clip(out, 0.0, 1.0)


def _ground_and_wall_albedo(name: str, u, v, f, q, vert, s):
    """Pavements, stone, concrete, brick, facades and floors (None: not one of those materials)."""
    if name == "asphalt":
        c = 0.25 + 0.5 * fbm(u, v, 0.8, 7, s, f) * 0.35 + 0.08 * fbm(u, v, 24.0, 2, s + 5, f)
        col = np.stack([c, c, c * 1.04], -1)
        # markings: dashed centre line, solid edge lines, a zebra crossing
        dash = box_mask(np.mod(u, 6.0), v, 0.0, 3.0, -16.08, -15.92, f)
        edge = np.maximum(box_mask(u, v, -1e9, 1e9, -19.7, -19.58, f), box_mask(u, v, -1e9, 1e9, -12.42, -12.3, f))
        zebra = lines(u, 1.0, 0.5, f, offset=0.25) * box_mask(u, v, -3.0, 0.5, -19.3, -12.7, f)
        m = np.clip(dash + edge + zebra, 0, 1) * (1.0 - vert)
        col = _mix(col, [0.88, 0.87, 0.8], 0.9 * m)
    elif name == "road":  # asphalt without the demo street's markings (districts draw theirs as geometry)
        c = 0.25 + 0.5 * fbm(u, v, 0.8, 7, s, f) * 0.35 + 0.08 * fbm(u, v, 24.0, 2, s + 5, f)
        col = np.stack([c, c, c * 1.04], -1)
    elif name == "marking":
        c = 0.84 + 0.08 * fbm(u, v, 6.0, 3, s, f)
        col = np.stack([c, c * 0.99, c * 0.92], -1)
    elif name == "granite":
        c = 0.56 + 0.3 * fbm(u, v, 20.0, 3, s, f)
        col = np.stack([c, c, c * 1.03], -1)
    elif name == "paving":
        rnd, j = _tiles(u, v, 0.4, 0.4, 0.015, f, s, bond=False)
        base = np.array([0.63, 0.6, 0.55]) * (0.88 + 0.24 * rnd)[:, None]
        col = _mix(base, [0.36, 0.35, 0.33], j) + 0.06 * fbm(u, v, 3.0, 4, s, f)[:, None]
    elif name == "plaza_stone":
        rnd, j = _tiles(u, v, 1.0, 0.5, 0.02, f, s, bond=True)
        base = _mix([0.76, 0.68, 0.55], [0.6, 0.55, 0.5], rnd)
        col = _mix(base, [0.4, 0.37, 0.33], j) + 0.05 * fbm(u, v, 5.0, 4, s, f)[:, None]
    elif name == "concrete":
        c = 0.6 + 0.25 * fbm(u, v, 1.5, 6, s, f) - 0.12 * lines(u, 1.2, 0.012, f) - 0.1 * lines(v, 0.6, 0.01, f)
        col = np.stack([c, c * 0.99, c * 0.96], -1)
    elif name in ("brick", "facade"):
        rnd, j = _tiles(u, v, 0.225, 0.075, 0.011, f, s, bond=True)
        base = _mix([0.58, 0.26, 0.17], [0.42, 0.2, 0.14], rnd)
        col = _mix(base, [0.74, 0.71, 0.66], j)
        if name == "facade":  # window grid above the ground floor
            wm = box_mask(np.mod(u, 3.0), np.mod(v - 0.15, 3.2), 0.8, 2.2, 0.9, 2.6, f) * (q[:, 2] > 3.0)
            frame = box_mask(np.mod(u, 3.0), np.mod(v - 0.15, 3.2), 0.7, 2.3, 0.8, 2.7, f) * (q[:, 2] > 3.0)
            wc = _mix([0.12, 0.16, 0.22], [0.35, 0.45, 0.55], hash01(np.floor(u / 3.0).astype(np.int64),
                                                                       np.floor(v / 3.2).astype(np.int64), s))
            col = _mix(_mix(col, [0.85, 0.85, 0.82], frame), wc, wm)
    elif name == "lobby_floor":
        cu, cv = np.floor(u / 0.6), np.floor(v / 0.6)
        chk = np.mod(cu + cv, 2)
        a = np.clip((f - 0.15) / 0.3, 0, 1)  # checker averages out beyond ~0.3 m footprints
        t = (1 - a) * chk + a * 0.5
        col = _mix([0.86, 0.84, 0.8], [0.3, 0.28, 0.27], t) + 0.08 * fbm(u, v, 4.0, 5, s, f)[:, None]
    else:
        return None
    return col


def _object_albedo(name: str, u, v, f, q, vert, s, car_color):
    """Interior finishes, wood, metal, plants, soil, the car, glass and rubber."""
    if name == "plaster":
        c = 0.86 + 0.08 * fbm(u, v, 2.0, 5, s, f)
        col = np.stack([c, c * 0.97, c * 0.9], -1)
        h = q[:, 2] - 0.15
        col = _mix(col, [0.45, 0.36, 0.3], box_mask(h, h, -1e9, 1.0, -1e9, 1e9, f) * vert)
    elif name == "ceiling":
        g = np.maximum(lines(u, 0.6, 0.02, f), lines(v, 0.6, 0.02, f))
        lamp = box_mask(np.mod(u, 3.0), np.mod(v, 3.0), 1.2, 1.8, 1.2, 1.8, f)
        col = _mix(_mix(np.full((len(u), 3), 0.9), [0.62, 0.62, 0.6], g), [1.0, 0.98, 0.9], lamp)
    elif name == "wood":
        w = 0.5 + 0.5 * np.sin(2 * np.pi * (v * 30.0 + 2.0 * fbm(u, v, 4.0, 3, s, f)))
        a = np.clip((f - 0.01) / 0.03, 0, 1)
        col = _mix([0.55, 0.36, 0.2], [0.4, 0.25, 0.13], (1 - a) * w + a * 0.5)
    elif name == "metal":
        c = 0.27 + 0.1 * fbm(u, v, 8.0, 3, s, f)
        col = np.stack([c, c * 1.02, c * 1.06], -1)
    elif name == "bark":
        c = 0.5 + 0.6 * fbm(u * 4.0, v, 3.0, 4, s, f)
        col = np.array([0.36, 0.24, 0.15]) * c[:, None]
    elif name == "foliage":
        c = 0.65 + 1.3 * fbm(q[:, 0] + q[:, 2], q[:, 1] - q[:, 2], 2.5, 5, s, f)
        col = np.array([0.2, 0.42, 0.13]) * c[:, None] + np.array([0.05, 0.02, 0.0]) * (c[:, None] > 0.9)
    elif name == "terracotta":
        col = np.array([0.68, 0.37, 0.24]) * (0.9 + 0.4 * fbm(u, v, 6.0, 3, s, f))[:, None]
    elif name == "soil":
        col = np.array([0.32, 0.23, 0.15]) * (0.85 + 0.6 * fbm(u, v, 10.0, 4, s, f))[:, None]
    elif name == "car_paint":
        col = np.asarray(car_color) * (0.95 + 0.1 * fbm(u, v, 2.0, 2, s, f))[:, None]
    elif name == "car_paint_light":
        col = np.array([0.8, 0.8, 0.78]) * (0.95 + 0.1 * fbm(u, v, 2.0, 2, s, f))[:, None]
    elif name == "glass":
        col = _mix([0.1, 0.13, 0.17], [0.3, 0.36, 0.42], np.clip(0.5 + fbm(u, v, 0.7, 2, s, f), 0, 1))
    elif name == "rubber":
        col = np.full((len(u), 3), 0.07)
    elif name == "grass":
        col = np.array([0.3, 0.5, 0.17]) * (0.8 + 0.9 * fbm(u, v, 3.0, 6, s, f))[:, None]
    else:  # pragma: no cover - MATERIALS and this table are edited together
        raise KeyError(f"textures.albedo: no texture for material {name!r}")
    return col


def lighting(n: np.ndarray, indoor: np.ndarray) -> np.ndarray:
    """View-independent light factor `[N]`: ambient + sun on the outward normal, constant indoors."""
    sun = AMBIENT + DIFFUSE * np.clip(n @ SUN, 0.0, None)
    return np.where(indoor, INDOOR_LIGHT, sun)


SHADE_CHUNK = 1 << 20  # points shaded at once: every step is per point, so chunks only bound the temporaries


def shade(material, p, n, fw, indoor, seed: int, car_color) -> np.ndarray:
    """Final linear colour `[N, 3]` in [0, 1]: albedo times lighting (in chunks of `SHADE_CHUNK` points)."""
    N = len(material)
    if N > SHADE_CHUNK:
        return np.concatenate([shade(material[a:a + SHADE_CHUNK], p[a:a + SHADE_CHUNK], n[a:a + SHADE_CHUNK],
                                     fw[a:a + SHADE_CHUNK], indoor[a:a + SHADE_CHUNK], seed, car_color)
                               for a in range(0, N, SHADE_CHUNK)])
    return np.clip(albedo(material, p, n, fw, seed, car_color) * lighting(n, indoor)[:, None], 0.0, 1.0)


def sky(directions: np.ndarray) -> np.ndarray:
    """Background colour `[N, 3]` for unit nav-frame ray directions `[N, 3]` that hit nothing."""
    t = np.clip(directions[:, 2] / 0.6, 0.0, 1.0)
    return _mix(SKY_HORIZON, SKY_ZENITH, t)
