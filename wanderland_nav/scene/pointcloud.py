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

from wanderland_nav.atomic import atomic_path


class PointCloudFormatError(ValueError):
    """A point-cloud file is missing, truncated or malformed (message names file and property)."""


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_NP_TO_PLY = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
              "f4": "float", "f8": "double"}


@dataclass
class PlyProperty:
    name: str
    dtype: str  # numpy kind+size, e.g. "f4"
    list_count_dtype: str | None = None  # set for `property list <count> <item> name`


@dataclass
class PlyElement:
    name: str
    count: int
    properties: list[PlyProperty]

    @property
    def has_list(self) -> bool:
        return any(p.list_count_dtype for p in self.properties)


@dataclass
class PlyHeader:
    fmt: str  # "ascii" | "binary_little_endian" | "binary_big_endian"
    elements: list[PlyElement]
    data_offset: int  # byte offset of the body
    comments: list[str]


def read_ply_header(path) -> PlyHeader:
    path = Path(path)
    if not path.is_file():
        raise PointCloudFormatError(f"{path}: file not found")
    with open(path, "rb") as f:
        head = f.read(1 << 16)
        end = head.find(b"end_header")
        while end < 0:
            more = f.read(1 << 16)
            if not more or len(head) > (1 << 24):
                raise PointCloudFormatError(f"{path}: no 'end_header' line (not a PLY file or truncated header)")
            head += more
            end = head.find(b"end_header")
    nl = head.find(b"\n", end)
    if nl < 0:
        raise PointCloudFormatError(f"{path}: header is not terminated by a newline after end_header")
    text = head[:end].decode("ascii", errors="replace").replace("\r", "")
    lines = text.split("\n")
    if not lines or lines[0].strip() != "ply":
        raise PointCloudFormatError(f"{path}: missing 'ply' magic line")
    fmt, elements, comments = None, [], []
    for raw in lines[1:]:
        tok = raw.split()
        if not tok:
            continue
        if tok[0] == "format":
            if len(tok) < 2 or tok[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise PointCloudFormatError(f"{path}: unsupported header field format {raw!r}")
            fmt = tok[1]
        elif tok[0] in ("comment", "obj_info"):
            comments.append(raw[len(tok[0]):].strip())
        elif tok[0] == "element":
            try:
                elements.append(PlyElement(tok[1], int(tok[2]), []))
            except (IndexError, ValueError):
                raise PointCloudFormatError(f"{path}: malformed header line {raw!r}") from None
        elif tok[0] == "property":
            if not elements:
                raise PointCloudFormatError(f"{path}: property before any element: {raw!r}")
            try:
                if tok[1] == "list":
                    elements[-1].properties.append(PlyProperty(tok[4], _PLY_TYPES[tok[3]], _PLY_TYPES[tok[2]]))
                else:
                    elements[-1].properties.append(PlyProperty(tok[2], _PLY_TYPES[tok[1]]))
            except (IndexError, KeyError):
                raise PointCloudFormatError(f"{path}: unsupported property line {raw!r}") from None
    if fmt is None:
        raise PointCloudFormatError(f"{path}: header has no 'format' line")
    return PlyHeader(fmt, elements, nl + 1, comments)


def _truncation_error(path, el: PlyElement, n_ok_bytes: int, stride: int, props: list[PlyProperty]):
    row, within = divmod(max(n_ok_bytes, 0), stride)
    acc = 0
    prop = props[-1].name
    for p in props:
        acc += np.dtype(p.dtype).itemsize
        if within < acc:
            prop = p.name
            break
    return PointCloudFormatError(
        f"{path}: truncated/corrupt data in element '{el.name}', property '{prop}' at row {row} "
        f"(header declares {el.count} rows)")


def read_ply(path) -> tuple[PlyHeader, dict[str, dict[str, np.ndarray]]]:
    """Read every element into `{element: {property: array[count]}}` (list properties -> object
    array unless every list has the same length, then a `[count, L]` array)."""
    path = Path(path)
    hdr = read_ply_header(path)
    data = path.read_bytes()[hdr.data_offset:]
    out: dict[str, dict[str, np.ndarray]] = {}
    if hdr.fmt == "ascii":
        _read_ascii_body(path, hdr, data, out)
        return hdr, out
    bo = "<" if hdr.fmt == "binary_little_endian" else ">"
    off = 0
    for el in hdr.elements:
        if not el.has_list:
            dt = np.dtype([(p.name, bo + p.dtype) for p in el.properties])
            need = dt.itemsize * el.count
            if off + need > len(data):
                raise _truncation_error(path, el, len(data) - off, dt.itemsize, el.properties)
            arr = np.frombuffer(data, dtype=dt, count=el.count, offset=off)
            out[el.name] = {p.name: arr[p.name].astype(np.dtype(p.dtype)) for p in el.properties}
            off += need
        else:
            off = _read_binary_list_element(path, el, data, off, bo, out)
    if off < len(data) and data[off:].strip(b"\x00\r\n \t"):
        # Trailing garbage usually means the header undercounts rows: refuse rather than guess.
        raise PointCloudFormatError(f"{path}: {len(data) - off} unexpected bytes after the last element "
                                    f"('{hdr.elements[-1].name}')")
    return hdr, out


def _read_binary_list_element(path, el: PlyElement, data: bytes, off: int, bo: str, out) -> int:
    """List elements (faces) have variable-size rows. Fast path: all lists equal length (triangles)."""
    res: dict[str, list] = {p.name: [] for p in el.properties}
    # Try the uniform layout first: probe the first row's list length(s).
    probe = off
    layout = []
    for p in el.properties:
        if p.list_count_dtype:
            cdt = np.dtype(bo + p.list_count_dtype)
            if probe + cdt.itemsize > len(data):
                if el.count == 0:
                    break
                raise _truncation_error(path, el, probe - off, 1, [p])
            L = int(np.frombuffer(data, cdt, 1, probe)[0]) if el.count else 0
            layout.append((p.name + "__count", bo + p.list_count_dtype))
            layout.append((p.name, bo + p.dtype, (L,)))
            probe += cdt.itemsize + np.dtype(p.dtype).itemsize * L
        else:
            layout.append((p.name, bo + p.dtype))
            probe += np.dtype(p.dtype).itemsize
    dt = np.dtype(layout) if layout else None
    if dt is not None and off + dt.itemsize * el.count <= len(data):
        arr = np.frombuffer(data, dtype=dt, count=el.count, offset=off)
        ok = all((arr[p.name + "__count"] == arr.dtype[p.name].shape[0]).all()
                 for p in el.properties if p.list_count_dtype)
        if ok:
            out[el.name] = {p.name: np.array(arr[p.name]).astype(np.dtype(p.dtype)) for p in el.properties}
            return off + dt.itemsize * el.count
    # Variable-length lists: sequential scan (rare for the files we read: polygons other than triangles).
    for row in range(el.count):
        for p in el.properties:
            if p.list_count_dtype:
                cdt = np.dtype(bo + p.list_count_dtype)
                if off + cdt.itemsize > len(data):
                    raise PointCloudFormatError(f"{path}: truncated data in element '{el.name}', property "
                                                f"'{p.name}' (list count) at row {row}")
                L = int(np.frombuffer(data, cdt, 1, off)[0])
                off += cdt.itemsize
                idt = np.dtype(bo + p.dtype)
                if off + idt.itemsize * L > len(data):
                    raise PointCloudFormatError(f"{path}: truncated data in element '{el.name}', property "
                                                f"'{p.name}' at row {row}")
                res[p.name].append(np.frombuffer(data, idt, L, off).astype(np.dtype(p.dtype)))
                off += idt.itemsize * L
            else:
                idt = np.dtype(bo + p.dtype)
                if off + idt.itemsize > len(data):
                    raise PointCloudFormatError(f"{path}: truncated data in element '{el.name}', property "
                                                f"'{p.name}' at row {row}")
                res[p.name].append(np.frombuffer(data, idt, 1, off)[0])
                off += idt.itemsize
    out[el.name] = {k: _maybe_stack(v) for k, v in res.items()}
    return off


def _maybe_stack(vals: list):
    if vals and isinstance(vals[0], np.ndarray):
        if len({v.shape for v in vals}) == 1:
            return np.stack(vals)
        o = np.empty(len(vals), dtype=object)
        o[:] = vals
        return o
    return np.asarray(vals)


def _read_ascii_body(path, hdr: PlyHeader, data: bytes, out) -> None:
    lines = data.decode("ascii", errors="replace").splitlines()
    pos = 0
    for el in hdr.elements:
        rows = lines[pos:pos + el.count]
        if len(rows) < el.count:
            raise PointCloudFormatError(
                f"{path}: truncated ascii data in element '{el.name}', property '{el.properties[0].name}' "
                f"at row {len(rows)} (header declares {el.count} rows)")
        pos += el.count
        if not el.has_list:
            nprop = len(el.properties)
            try:
                tok = " ".join(rows).split()
                vals = np.asarray(tok, dtype=np.float64)
            except ValueError:
                vals = None
            if vals is None or vals.size != nprop * el.count:
                # locate the offending row/property for the message
                for r, line in enumerate(rows):
                    t = line.split()
                    for j, p in enumerate(el.properties):
                        if j >= len(t):
                            raise PointCloudFormatError(f"{path}: ascii element '{el.name}' row {r}: "
                                                        f"missing property '{p.name}'")
                        try:
                            float(t[j])
                        except ValueError:
                            raise PointCloudFormatError(f"{path}: ascii element '{el.name}' row {r}: property "
                                                        f"'{p.name}' is not a number: {t[j]!r}") from None
                    if len(t) > nprop:
                        raise PointCloudFormatError(f"{path}: ascii element '{el.name}' row {r}: {len(t)} values, "
                                                    f"header declares {nprop} properties")
                raise PointCloudFormatError(f"{path}: corrupt ascii element '{el.name}'")
            vals = vals.reshape(el.count, nprop)
            out[el.name] = {p.name: vals[:, j].astype(np.dtype(p.dtype)) for j, p in enumerate(el.properties)}
        else:
            res: dict[str, list] = {p.name: [] for p in el.properties}
            for r, line in enumerate(rows):
                t = line.split()
                k = 0
                try:
                    for p in el.properties:
                        if p.list_count_dtype:
                            L = int(t[k])
                            k += 1
                            if k + L > len(t):
                                raise IndexError
                            res[p.name].append(np.asarray(t[k:k + L], dtype=np.float64).astype(np.dtype(p.dtype)))
                            k += L
                        else:
                            res[p.name].append(np.dtype(p.dtype).type(float(t[k])))
                            k += 1
                except (IndexError, ValueError):
                    raise PointCloudFormatError(f"{path}: ascii element '{el.name}' row {r}: property "
                                                f"'{p.name}' missing or not a number") from None
            out[el.name] = {k2: _maybe_stack(v) for k2, v in res.items()}


# --------------------------------------------------------------------------- point clouds


@dataclass
class PointCloud:
    """`xyz [N,3] float32` (file frame, metres); `rgb [N,3] uint8` or None; other vertex properties in `extra`."""

    xyz: np.ndarray
    rgb: np.ndarray | None
    extra: dict[str, np.ndarray]

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


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
        if a.dtype.str[1:] not in _NP_TO_PLY:
            a = a.astype(np.float32)
        cols.append((k, a))
    write_ply_element(path, "vertex", cols, binary=binary, comments=comments)


def write_ply_element(path, element: str, cols: list[tuple[str, np.ndarray]], *, binary: bool = True,
                      comments: tuple[str, ...] = (), extra_elements_bytes: tuple = ()) -> None:
    """Write one scalar-property element (columns in order) as PLY, atomically."""
    n = cols[0][1].shape[0] if cols else 0
    fmt = "binary_little_endian" if binary else "ascii"
    head = ["ply", f"format {fmt} 1.0", *[f"comment {c}" for c in comments], f"element {element} {n}"]
    for name, a in cols:
        head.append(f"property {_NP_TO_PLY[np.asarray(a).dtype.str[1:]]} {name}")
    head.append("end_header")
    header = ("\n".join(head) + "\n").encode("ascii")
    if binary:
        dt = np.dtype([(name, "<" + np.asarray(a).dtype.str[1:]) for name, a in cols])
        rec = np.empty(n, dtype=dt)
        for name, a in cols:
            rec[name] = a
        body = rec.tobytes()
    else:
        parts = []
        for name, a in cols:
            a = np.asarray(a)
            parts.append(a.astype(str) if a.dtype.kind in "iu" else np.char.mod("%.9g", a.astype(np.float64)))
        body = ("\n".join(" ".join(r) for r in zip(*parts)) + ("\n" if n else "")).encode("ascii")
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + body)


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
