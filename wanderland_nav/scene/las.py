"""ASPRS LAS point clouds (Wanderland v2 `lidar/colorized.las`) read with `laspy`, in bounded memory.

LAS stores coordinates as scaled 32-bit integers (`X * scale + offset`); `laspy` applies the scale and
offset, we keep metres. Colours are 16-bit in LAS (0..65535) although many writers put 8-bit values in
them; both are mapped to `uint8`. The file is read `chunk_points` records at a time into preallocated
float32 / uint8 arrays, so a cloud of tens of millions of points never exists as float64 or as laspy
records in full (peak extra memory: one chunk).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from wanderland_nav.scene.pointcloud import PointCloud, PointCloudFormatError

log = logging.getLogger(__name__)

_FLOAT32_SAFE = 1e4  # metres: beyond this a float32 coordinate is coarser than 1 mm


def _colour_to_u8(c: np.ndarray, sixteen_bit: bool) -> np.ndarray:
    return (c >> 8).astype(np.uint8) if sixteen_bit else np.clip(c, 0, 255).astype(np.uint8)


def read_las_points(path, chunk_points: int = 2_000_000) -> PointCloud:
    """`PointCloud` (xyz float32 metres, rgb uint8 or None, `extra["intensity"]` uint16) of a LAS/LAZ file."""
    try:
        import laspy
    except ImportError:
        raise PointCloudFormatError(f"{path}: reading LAS needs laspy (pip install 'wanderland_nav[las]')") from None
    path = Path(path)
    if not path.is_file():
        raise PointCloudFormatError(f"{path}: file not found")
    try:
        reader = laspy.open(path)
    except (laspy.errors.LaspyException, OSError, ValueError) as e:
        raise PointCloudFormatError(f"{path}: not a readable LAS file ({e})") from None
    with reader:
        hdr = reader.header
        n = int(hdr.point_count)
        if n == 0:
            raise PointCloudFormatError(f"{path}: empty scan (header point_count 0)")
        dims = set(hdr.point_format.dimension_names)
        has_rgb = {"red", "green", "blue"} <= dims
        xyz = np.empty((n, 3), np.float32)
        rgb = np.empty((n, 3), np.uint16) if has_rgb else None
        inten = np.empty(n, np.uint16)
        s = 0
        try:
            for pts in reader.chunk_iterator(chunk_points):  # scaled ints -> metres, chunk by chunk
                m = len(pts)
                xyz[s:s + m] = np.stack([np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)], -1)
                if has_rgb:
                    rgb[s:s + m] = np.stack([pts.red, pts.green, pts.blue], -1)
                inten[s:s + m] = pts.intensity
                s += m
        except (laspy.errors.LaspyException, ValueError) as e:
            raise PointCloudFormatError(f"{path}: truncated or corrupt point records after {s} of {n} ({e})") from None
    if s != n:
        raise PointCloudFormatError(f"{path}: header declares {n} points (point_count) but the file holds {s}")
    if np.abs(xyz).max() > _FLOAT32_SAFE:
        log.warning("%s: coordinates reach %.0f m from the origin: float32 keeps them to %.3f m", path,
                    np.abs(xyz).max(), np.spacing(np.float32(np.abs(xyz).max())))
    if rgb is not None:
        rgb = _colour_to_u8(rgb, sixteen_bit=bool(rgb.max() > 255))
    return PointCloud(xyz, rgb, {"intensity": inten})
