"""3DGS PLY tables: thin wrappers over `plyfile` (`wanderland_nav.render.plyio`) that raise `PlyError`.

Properties are always addressed by name, never by position, because exporters reorder them (INRIA
writes `f_dc, f_rest, opacity, scale, rot`; PlayCanvas writes `scale` first). Binary files of either
byte order are memory-mapped, ASCII files are parsed; a truncated or malformed file raises `PlyError`
naming the file (and the element, row and property where plyfile can tell).
"""

from __future__ import annotations

import os

import numpy as np

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.render.plyio import element_table, read_ply_data, write_ply_table


class PlyError(WanderlandInputError):
    """A PLY file that cannot be read as a vertex table; the message names the file."""


def read_ply_element(path: str | os.PathLike, element: str = "vertex") -> np.ndarray:
    """One element of a PLY as a structured array `[count]` (fields named as in the file).

    For binary files this is a copy-on-write memory map in the file's byte order: read fields by
    name and convert them (`.astype`) before handing them to torch.
    """
    return element_table(read_ply_data(path, PlyError), path, element, PlyError)


def write_ply_element(path: str | os.PathLike, table: np.ndarray, element: str = "vertex") -> None:
    """Write a structured array as a binary little-endian PLY with one element, atomically."""
    write_ply_table(path, table, element)
