"""Minimal binary PLY reader/writer for flat vertex tables (numpy structured arrays).

Why our own: render/ may import torch and numpy only, and 3DGS PLYs are a single `vertex`
element of scalar properties, which numpy's structured dtypes read in one `frombuffer` call.
Properties are always addressed by name, never by position, because exporters reorder them
(INRIA writes `f_dc, f_rest, opacity, scale, rot`; PlayCanvas writes `scale` first).

Supported: `binary_little_endian` / `binary_big_endian` 1.0, scalar properties of every PLY type,
other elements before `vertex` as long as their rows have a fixed size. Everything else (ASCII
files, list properties in or before `vertex`, truncated data) raises `PlyError` naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError

# PLY scalar type name -> numpy type code (byte order added per file)
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_NP_TO_PLY = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
              "f4": "float", "f8": "double"}
_MAX_HEADER = 1 << 20  # a header longer than 1 MiB is not a PLY we can read


class PlyError(WanderlandInputError):
    """A PLY file that cannot be read as a binary vertex table; the message names the file."""


def _parse_header(path: Path, raw: bytes) -> tuple[str, list[tuple[str, int, list[tuple[str, str]] | None]], int]:
    """Returns (byte order char, [(element name, count, [(prop, np code)] or None if it has lists)], data offset)."""
    if not raw.startswith(b"ply"):
        raise PlyError(f"{path}: not a PLY file (missing 'ply' magic)")
    end = raw.find(b"end_header", 0, _MAX_HEADER)
    if end < 0:
        raise PlyError(f"{path}: PLY header has no 'end_header' (truncated or not a PLY file)")
    nl = raw.find(b"\n", end)
    if nl < 0:
        raise PlyError(f"{path}: PLY header ends without a newline after 'end_header' (truncated)")
    lines = raw[:end].decode("ascii", errors="replace").replace("\r", "").split("\n")
    order = None
    elements: list[tuple[str, int, list[tuple[str, str]] | None]] = []
    for ln, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            if len(tok) < 2 or tok[1] not in ("binary_little_endian", "binary_big_endian"):
                raise PlyError(f"{path}: header line {ln}: format {' '.join(tok[1:])!r} is not supported; "
                               "only binary_little_endian / binary_big_endian PLY files can be read")
            order = "<" if tok[1] == "binary_little_endian" else ">"
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise PlyError(f"{path}: header line {ln}: malformed element line {line!r}")
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property":
            if not elements:
                raise PlyError(f"{path}: header line {ln}: property before any element")
            name, count, props = elements[-1]
            if len(tok) >= 2 and tok[1] == "list":
                elements[-1] = (name, count, None)  # variable-size rows
                continue
            if len(tok) != 3 or tok[1] not in _PLY_TYPES:
                raise PlyError(f"{path}: header line {ln}: unsupported property line {line!r}")
            if props is not None:
                if any(p == tok[2] for p, _ in props):
                    raise PlyError(f"{path}: element {name!r} declares property {tok[2]!r} twice")
                props.append((tok[2], _PLY_TYPES[tok[1]]))
        else:
            raise PlyError(f"{path}: header line {ln}: unknown keyword {tok[0]!r}")
    if order is None:
        raise PlyError(f"{path}: PLY header has no 'format' line")
    return order, elements, nl + 1


def read_ply_element(path: str | os.PathLike, element: str = "vertex") -> np.ndarray:
    """Read one element of a binary PLY as a structured array `[count]` (fields named as in the file).

    The returned array is a copy in native byte order, so callers can index fields by name and
    hand them to torch directly.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise PlyError(f"{path}: cannot read PLY file ({e})") from e
    order, elements, offset = _parse_header(path, raw)
    for name, count, props in elements:
        if props is None:
            if name == element:
                raise PlyError(f"{path}: element {name!r} has list properties, which are not supported")
            raise PlyError(f"{path}: element {name!r} before {element!r} has list properties; cannot locate "
                           f"{element!r} data")
        dtype = np.dtype([(p, order + code) for p, code in props])
        if name == element:
            need = offset + count * dtype.itemsize
            if len(raw) < need:
                raise PlyError(f"{path}: truncated PLY: element {element!r} needs {count} x {dtype.itemsize} bytes "
                               f"but the file ends {need - len(raw)} bytes early")
            arr = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
            return arr.astype(dtype.newbyteorder("="), copy=True)
        offset += count * dtype.itemsize
    raise PlyError(f"{path}: PLY has no element {element!r} (elements: {[e[0] for e in elements]})")


def write_ply_element(path: str | os.PathLike, table: np.ndarray, element: str = "vertex") -> None:
    """Write a structured array as a binary little-endian PLY with one element, atomically."""
    if table.dtype.names is None:
        raise ValueError(f"{path}: write_ply_element needs a structured array, got dtype {table.dtype}")
    le = np.dtype([(n, table.dtype[n].newbyteorder("<")) for n in table.dtype.names])
    lines = ["ply", "format binary_little_endian 1.0", f"element {element} {len(table)}"]
    for n in table.dtype.names:
        code = table.dtype[n].str[1:]
        if code not in _NP_TO_PLY:
            raise ValueError(f"{path}: field {n!r} has dtype {table.dtype[n]} with no PLY scalar type")
        lines.append(f"property {_NP_TO_PLY[code]} {n}")
    lines.append("end_header")
    header = ("\n".join(lines) + "\n").encode("ascii")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(header)
            f.write(np.ascontiguousarray(table.astype(le)).tobytes())
