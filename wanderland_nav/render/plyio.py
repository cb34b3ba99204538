"""PLY files through `plyfile`, with errors that name the file, element, row and property.

One reader and one writer for every PLY the framework touches (3DGS splats in `render/`, point
clouds in `scene/`). `plyfile` memory-maps binary elements of fixed-size rows (a 3DGS file is read
without copying it), reads ASCII and both byte orders, and writes exactly the header and body bytes
a hand-written codec would. What this module adds:

* errors raised as the caller's `ValueError` subclass, with the file path first, and for a
  truncated binary element the property where the data ran out;
* fast reads of triangle-like list properties: the first row's list length is tried as a known
  length (memory-mapped); only genuinely ragged lists fall back to plyfile's per-row reader;
* atomic writes (`wanderland_nav.atomic`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import plyfile

from wanderland_nav.atomic import atomic_path


def read_ply_data(path: str | os.PathLike, error: type[ValueError] = ValueError) -> plyfile.PlyData:
    """Parse a PLY file (ascii or binary); every failure raises `error` naming `path`."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: file not found")
    try:
        lengths, end = _binary_layout(path)
        data = plyfile.PlyData.read(str(path), known_list_len=lengths)
        _check_no_trailing_bytes(path, end, error)
        return data
    except plyfile.PlyElementParseError as e:
        if "unexpected list length" not in str(e):
            raise error(_element_message(path, e)) from None
    except plyfile.PlyHeaderParseError as e:
        magic = " (missing 'ply' magic: not a PLY file)" if e.line == 1 else ""
        raise error(f"{path}: malformed PLY header: {e}{magic}") from None
    except (OSError, ValueError) as e:
        raise error(f"{path}: cannot read PLY file ({e})") from None
    try:  # ragged lists (polygons of mixed size): plyfile's row-by-row reader
        return plyfile.PlyData.read(str(path), mmap=False)
    except plyfile.PlyParseError as e:
        raise error(_element_message(path, e)) from None


def element_table(data: plyfile.PlyData, path, name: str, error: type[ValueError] = ValueError) -> np.ndarray:
    """The structured array `[count]` of element `name` (fields named as in the file), or `error`."""
    if name not in [e.name for e in data.elements]:
        raise error(f"{path}: PLY has no element {name!r} (elements: {[e.name for e in data.elements]})")
    return data[name].data


def write_ply_table(path: str | os.PathLike, table: np.ndarray, element: str = "vertex", *, binary: bool = True,
                    comments: tuple[str, ...] = ()) -> None:
    """Write a structured array of scalar fields as one PLY element (little-endian or ascii), atomically."""
    if table.dtype.names is None:
        raise ValueError(f"{path}: a PLY element needs a structured array, got dtype {table.dtype}")
    try:
        el = plyfile.PlyElement.describe(table, element)
    except ValueError as e:
        raise ValueError(f"{path}: element {element!r}: {e}") from None
    ply = plyfile.PlyData([el], text=not binary, byte_order="<", comments=list(comments))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            ply.write(f)


def write_ply_chunks(path: str | os.PathLike, dtype: np.dtype, count: int, chunks, element: str = "vertex") -> None:
    """Write `count` rows of the structured `dtype` as one binary little-endian PLY element, atomically, from
    `chunks` (an iterable of structured arrays of that dtype whose lengths sum to `count`): the bytes of
    `write_ply_table` on their concatenation, without ever holding the whole table (a paper-size splat's is 1.8 GB)."""
    dtype = np.dtype(dtype)
    if dtype.names is None:
        raise ValueError(f"{path}: a PLY element needs a structured dtype, got {dtype}")
    try:
        el = plyfile.PlyElement.describe(np.empty(0, dtype=dtype), element)
    except ValueError as e:
        raise ValueError(f"{path}: element {element!r}: {e}") from None
    header = plyfile.PlyData([el], text=False, byte_order="<").header
    zero = f"element {element} 0"
    if header.count(zero) != 1:
        raise ValueError(f"{path}: unexpected PLY header for element {element!r}")
    header = header.replace(zero, f"element {element} {int(count)}")
    le = dtype.newbyteorder("<")
    written = 0
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(header.encode("ascii") + b"\n")
            for part in chunks:
                if part.dtype.names != dtype.names:
                    raise ValueError(f"{path}: a chunk's fields {part.dtype.names} differ from {dtype.names}")
                f.write(np.ascontiguousarray(part, dtype=le).tobytes())
                written += len(part)
            if written != count:
                raise ValueError(f"{path}: {written} rows written, {count} announced")


def _binary_layout(path: Path) -> tuple[dict[str, dict[str, int]], int | None]:
    """(`known_list_len` for plyfile: each binary list property's first-row length (triangles: 3),
    the byte offset where the data ends if every list keeps that length; None for ascii)."""
    with open(path, "rb") as f:
        head = plyfile.PlyData._parse_header(f)
        if head.text:
            return {}, None
        offset = f.tell()
        out: dict[str, dict[str, int]] = {}
        for el in head.elements:
            lists = [p for p in el.properties if isinstance(p, plyfile.PlyListProperty)]
            if not lists:
                offset += el.count * el.dtype(head.byte_order).itemsize
                continue
            if el.count == 0:
                out[el.name] = {p.name: 0 for p in lists}
                continue
            f.seek(offset)
            lengths, size = {}, 0
            for p in el.properties:  # walk the first row
                if isinstance(p, plyfile.PlyListProperty):
                    len_dt, val_dt = p.list_dtype(head.byte_order)
                    raw = f.read(np.dtype(len_dt).itemsize)
                    if len(raw) < np.dtype(len_dt).itemsize:
                        return out, None
                    n = int(np.frombuffer(raw, len_dt)[0])
                    lengths[p.name] = n
                    f.seek(n * np.dtype(val_dt).itemsize, os.SEEK_CUR)
                    size += np.dtype(len_dt).itemsize + n * np.dtype(val_dt).itemsize
                else:
                    f.seek(np.dtype(p.dtype(head.byte_order)).itemsize, os.SEEK_CUR)
                    size += np.dtype(p.dtype(head.byte_order)).itemsize
            out[el.name] = lengths
            offset += el.count * size  # only right if every row has the first row's lengths: checked by plyfile
        return out, offset


def _check_no_trailing_bytes(path: Path, end: int | None, error: type[ValueError]) -> None:
    """Bytes after the last element usually mean the header undercounts rows: refuse rather than guess."""
    if end is None:
        return
    with open(path, "rb") as f:
        f.seek(end)
        rest = f.read(1 << 16)
    if rest.strip(b"\x00\r\n \t"):
        raise error(f"{path}: {Path(path).stat().st_size - end} unexpected bytes after the last element")


def _element_message(path: Path, e: plyfile.PlyParseError) -> str:
    """`path: truncated/corrupt data in element 'vertex', property 'green' at row 9 (...)`."""
    el = getattr(e, "element", None)
    if el is None:
        return f"{path}: {e}"
    prop = e.prop.name if getattr(e, "prop", None) is not None else _property_at_cut(path, el.name, e.row)
    where = f"element '{el.name}'" + (f", property '{prop}'" if prop else "") + f" at row {e.row}"
    return f"{path}: truncated/corrupt data in {where} (header declares {el.count} rows): {e.message}"


def _property_at_cut(path: Path, element: str, row: int | None) -> str | None:
    """For a binary element of fixed-size rows cut short: the property whose bytes ran out in `row`."""
    try:
        with open(path, "rb") as f:
            head = plyfile.PlyData._parse_header(f)
            offset, size = f.tell(), f.seek(0, os.SEEK_END)
    except (OSError, plyfile.PlyParseError):
        return None
    if head.text or row is None:
        return None
    for el in head.elements:
        if any(isinstance(p, plyfile.PlyListProperty) for p in el.properties):
            return None
        dt = el.dtype(head.byte_order)
        if el.name == element:
            within = size - offset - row * dt.itemsize  # bytes present of the cut row
            for name in dt.names:
                if within < dt.fields[name][1] + dt[name].itemsize:
                    return name
            return None
        offset += el.count * dt.itemsize
    return None
