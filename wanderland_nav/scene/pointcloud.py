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

from wanderland_nav.render.plyio import read_ply_data, write_ply_table
from wanderland_nav.errors import WanderlandInputError


class PointCloudFormatError(WanderlandInputError):
    """A point-cloud file is missing, truncated or malformed (message names file and property)."""


def read_ply(path) -> tuple[plyfile.PlyData, dict[str, dict[str, np.ndarray]]]:
    """Read every element into `{element: {property: array[count]}}` (native byte order; a list
    property is `[count, L]` when every list has the same length, else an object array).

    Parsing is `plyfile`'s (`wanderland_nav.render.plyio`); errors are `PointCloudFormatError` naming the file,
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


#: point-cloud files a v2 `lidar/` folder may hold
LIDAR_SUFFIXES = (".ply", ".bin", ".las", ".laz")
#: `.bin` record layouts seen in the wild: name -> (numpy dtype, values per record). Only KITTI's is read;
#: the others are recognised so that the error names the format instead of returning garbage points.
BIN_RECORD_FORMATS = {
    "KITTI float32 x y z intensity": ("<f4", 4),
    "nuScenes float32 x y z intensity ring": ("<f4", 5),
    "float64 x y z intensity": ("<f8", 4),
    "float64 x y z": ("<f8", 3),
}
_KITTI = "KITTI float32 x y z intensity"


def _plausible_scan(rec: np.ndarray) -> bool:
    """Whether `[N, C]` records look like a real scan: finite x/y/z within 10 km, not mostly denormal
    (a float64 read as float32), and a non-negative intensity column (a shifted record puts x/y there)."""
    with np.errstate(invalid="ignore"):  # signalling NaNs in misread bytes
        xyz = rec[:, :3].astype(np.float64)
    if not np.isfinite(xyz).all() or (np.abs(xyz) > 1e4).any():
        return False
    tiny = (np.abs(xyz) < 1e-20) & (xyz != 0)
    if tiny.mean() > 0.01:
        return False
    return rec.shape[1] < 4 or bool((rec[:, 3] >= 0).all())


def bin_formats_fitting(path) -> list[str]:
    """Names of `BIN_RECORD_FORMATS` whose record size divides the file size and whose values look like a scan."""
    path = Path(path)
    size = path.stat().st_size
    out = []
    for name, (dt, c) in BIN_RECORD_FORMATS.items():
        rec_bytes = np.dtype(dt).itemsize * c
        if size and size % rec_bytes == 0:
            rec = np.fromfile(path, dtype=dt).reshape(-1, c)
            if _plausible_scan(rec):
                out.append(name)
    return out


def read_kitti_bin(path) -> np.ndarray:
    """KITTI Velodyne scan: float32 `x y z intensity` records -> `[N,4]` float32 (sensor frame, z up).

    The file size must be a whole number of 16-byte records and the values must look like a scan;
    otherwise the error names the byte count and any other known record format that fits."""
    path = Path(path)
    if not path.is_file():
        raise PointCloudFormatError(f"{path}: file not found")
    size = path.stat().st_size
    if size == 0:
        raise PointCloudFormatError(f"{path}: empty scan (0 bytes, no points)")
    if size % 16 == 0:
        pts = np.fromfile(path, dtype="<f4").reshape(-1, 4)
        if _plausible_scan(pts):
            return pts
    fits = bin_formats_fitting(path)
    hint = (f"; it looks like {' or '.join(repr(f) for f in fits)} records: convert it to KITTI float32 "
            "x y z intensity") if fits else ""
    if size % 16:
        n, rest = divmod(size, 16)
        names = ("x", "y", "z", "intensity")
        raise PointCloudFormatError(
            f"{path}: {size} bytes is not a whole number of 16-byte KITTI records (float32 x y z intensity): "
            f"{n} records + {rest} bytes, the last record stops in property '{names[rest // 4]}'{hint}")
    raise PointCloudFormatError(
        f"{path}: {size} bytes read as KITTI float32 x y z intensity records give implausible points "
        f"(non-finite or beyond 10 km, denormal, or negative intensity){hint}")


def read_points_any(path) -> PointCloud:
    """A LiDAR frame from `.ply`, KITTI-style `.bin` or `.las`/`.laz` (what v2 `lidar/` folders contain)."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf == ".ply":
        return read_ply_points(path)
    if suf in LIDAR_SUFFIXES[2:]:
        from wanderland_nav.scene.las import read_las_points  # laspy is an optional dependency

        return read_las_points(path)
    if suf == ".bin":
        p = read_kitti_bin(path)
        return PointCloud(np.ascontiguousarray(p[:, :3]), None, {"intensity": p[:, 3].copy()})
    raise PointCloudFormatError(f"{path}: unsupported point-cloud format '{suf}' (expected one of {LIDAR_SUFFIXES})")
