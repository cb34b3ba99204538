"""Point-cloud file I/O: PLY (ascii / binary little- and big-endian) and KITTI Velodyne `.bin`.

PLY files from LiDAR tools, COLMAP, Open3D and 3DGS trainers differ in property order, extra
properties (normals, intensity, f_dc_*, ...) and types (float vs double, uchar vs float colour),
so everything is read **by property name**, never by position. A truncated or corrupt file
raises `PointCloudFormatError` naming the file, the element and the property where the data
ran out, because a silently short cloud gives a silently wrong collision mesh.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from wanderland_nav.plyio import read_ply_data, write_ply_table
from wanderland_nav.errors import WanderlandInputError


class PointCloudFormatError(WanderlandInputError):
    """A point-cloud file is missing, truncated or malformed (message names file and property)."""


def read_ply(path) -> tuple[plyfile.PlyData, dict[str, dict[str, np.ndarray]]]:
    """Read every element into `{element: {property: array[count]}}` (native byte order; a list
    property is `[count, L]` when every list has the same length, else an object array).

    Parsing is `plyfile`'s (`wanderland_nav.plyio`); errors are `PointCloudFormatError` naming the file,
    element, row and property."""
    data = read_ply_data(path, PointCloudFormatError)
    out = {}
    for el in data.elements:
        table = el.data
        out[el.name] = {n: _native(np.asarray(table[n])) for n in table.dtype.names}
    return data, out


def _native(a: np.ndarray) -> np.ndarray:
    return a if a.dtype.kind == "O" or a.dtype.isnative else a.astype(a.dtype.newbyteorder("="))


# --------------------------------------------------------------------------- point clouds


@dataclass
class PointCloud:
    """`xyz [N,3] float32` (file frame, metres); `rgb [N,3] uint8` or None; other vertex properties in `extra`."""

    xyz: np.ndarray
    rgb: np.ndarray | None
    extra: dict[str, np.ndarray]

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


_PLY_SCALARS = {"i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8"}  # numpy types a PLY property can hold
_COLOR_NAMES = (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue"))


def read_ply_points(path, *, element: str = "vertex", require_color: bool = False) -> PointCloud:
    """Read the `vertex` element of a PLY as a point cloud (x, y, z; red/green/blue if present)."""
    path = Path(path)
    _, els = read_ply(path)
    if element not in els:
        raise PointCloudFormatError(f"{path}: no element '{element}' (has {sorted(els)})")
    v = els[element]
    for k in ("x", "y", "z"):
        if k not in v:
            raise PointCloudFormatError(f"{path}: element '{element}' has no property '{k}' (has {sorted(v)})")
    xyz = np.stack([v["x"], v["y"], v["z"]], -1).astype(np.float32)
    rgb = None
    used = {"x", "y", "z"}
    for names in _COLOR_NAMES:
        if all(n in v for n in names):
            cols = np.stack([v[n] for n in names], -1)
            if np.issubdtype(cols.dtype, np.floating):
                # float colours are in [0, 1] by convention (Open3D); anything larger is 0..255
                scale = 255.0 if cols.size == 0 or np.nanmax(cols) <= 1.0 else 1.0
                cols = np.clip(np.round(cols * scale), 0, 255)
            elif cols.dtype.itemsize > 1:
                cols = np.clip(cols, 0, 255) if cols.size == 0 or cols.max() <= 255 else cols >> (8 * (cols.dtype.itemsize - 1))
            rgb = cols.astype(np.uint8)
            used |= set(names)
            break
    if require_color and rgb is None:
        raise PointCloudFormatError(f"{path}: element '{element}' has no red/green/blue properties")
    extra = {k: a for k, a in v.items() if k not in used}
    return PointCloud(xyz, rgb, extra)


def write_ply_points(path, xyz, rgb=None, *, binary: bool = True, extra: dict[str, np.ndarray] | None = None,
                     comments: tuple[str, ...] = ()) -> None:
    """Write `xyz [N,3]` (float32) + optional `rgb [N,3]` uint8 + optional scalar `extra` columns, atomically."""
    xyz = np.asarray(xyz, dtype=np.float32).reshape(-1, 3)
    n = xyz.shape[0]
    cols = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2])]
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.shape != (n, 3):
            raise ValueError(f"rgb must be [{n},3], got {rgb.shape}")
        if rgb.dtype != np.uint8:
            if rgb.size and (rgb.min() < 0 or rgb.max() > 255):
                raise ValueError("rgb values must be in 0..255")
            rgb = rgb.astype(np.uint8)
        cols += [("red", rgb[:, 0]), ("green", rgb[:, 1]), ("blue", rgb[:, 2])]
    for k, a in (extra or {}).items():
        a = np.asarray(a)
        if a.shape != (n,):
            raise ValueError(f"extra property '{k}' must be [{n}], got {a.shape}")
        if a.dtype.str[1:] not in _PLY_SCALARS:
            a = a.astype(np.float32)  # no PLY scalar type (bool, int64, float16, ...): store as float
        cols.append((k, a))
    write_ply_element(path, "vertex", cols, binary=binary, comments=comments)


def write_ply_element(path, element: str, cols: list[tuple[str, np.ndarray]], *, binary: bool = True,
                      comments: tuple[str, ...] = ()) -> None:
    """Write one scalar-property element (columns in order) as PLY (little-endian or ascii), atomically."""
    n = cols[0][1].shape[0] if cols else 0
    rec = np.empty(n, dtype=[(name, "<" + np.asarray(a).dtype.str[1:]) for name, a in cols])
    for name, a in cols:
        rec[name] = a
    write_ply_table(path, rec, element, binary=binary, comments=comments)


# --------------------------------------------------------------------------- KITTI


def read_kitti_bin(path) -> np.ndarray:
    """KITTI Velodyne scan: float32 `x y z intensity` records -> `[N,4]` float32 (sensor frame, z up)."""
    path = Path(path)
    if not path.is_file():
        raise PointCloudFormatError(f"{path}: file not found")
    raw = np.fromfile(path, dtype="<f4")
    if raw.size % 4:
        names = ("x", "y", "z", "intensity")
        raise PointCloudFormatError(f"{path}: truncated KITTI scan: {raw.size * 4} bytes is not a multiple of 16 "
                                    f"(last record stops before property '{names[raw.size % 4]}')")
    pts = raw.reshape(-1, 4)
    if not np.isfinite(pts[:, :3]).all():
        raise PointCloudFormatError(f"{path}: non-finite x/y/z in {int((~np.isfinite(pts[:, :3])).any(-1).sum())} points")
    return pts


def read_points_any(path) -> PointCloud:
    """A LiDAR frame from `.ply` or KITTI-style `.bin` (what v2 `lidar/` folders contain)."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf == ".ply":
        return read_ply_points(path)
    if suf == ".bin":
        p = read_kitti_bin(path)
        return PointCloud(np.ascontiguousarray(p[:, :3]), None, {"intensity": p[:, 3].copy()})
    raise PointCloudFormatError(f"{path}: unsupported point-cloud format '{suf}' (expected .ply or .bin)")
