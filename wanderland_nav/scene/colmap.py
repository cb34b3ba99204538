"""COLMAP sparse-model readers and writers (`cameras`, `images`, `points3D`, `.bin` and `.txt`).

Written from COLMAP's documented format (colmap/src/colmap/scene/reconstruction_io.cc) so a
Wanderland v1 folder loads without COLMAP or pycolmap installed, and so the demo scene can be
written in exactly the layout real captures use.

Conventions (COLMAP's, kept as is on disk):
* an image stores **cam_from_world**: quaternion `qvec` (w, x, y, z) and translation `tvec`,
  so `p_cam = R(qvec) @ p_world + tvec`; `ColmapImage.world_from_cam()` inverts it;
* binary files are little-endian; `point3D_id == -1` marks a 2D feature without a 3D point;
* camera models are identified by id in `.bin` and by name in `.txt` (`CAMERA_MODELS`).

Every read error (missing file, truncated/corrupt record, unknown model, bad text line) raises
`ColmapFormatError` naming the file and the field, because a half-read model silently
corrupts everything downstream.

The data classes live in `scene.colmap_types` and the text format (`.txt`) in `scene.colmap_text`;
this module reads and writes the binary format and whole models, and re-exports both.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.scene.colmap_text import (  # noqa: F401 - the text format, re-exported
    read_cameras_txt,
    read_images_txt,
    read_points3D_txt,
    write_cameras_txt,
    write_images_txt,
    write_points3D_txt,
)
from wanderland_nav.scene.colmap_types import (  # noqa: F401 - the data, re-exported
    CAMERA_MODELS,
    CAMERA_MODELS_BY_NAME,
    FISHEYE_MODELS,
    CameraModel,
    ColmapCamera,
    ColmapFormatError,
    ColmapImage,
    ColmapModel,
    ColmapPoints3D,
    camera_model,
    qvec_to_rotmat,
    rotmat_to_qvec,
)


# --------------------------------------------------------------------------- binary helpers


class _BinReader:
    """Sequential little-endian reader that names file and field when the data runs out."""

    def __init__(self, path: Path):
        self.path = Path(path)
        if not self.path.is_file():
            raise ColmapFormatError(f"{self.path}: file not found")
        self.buf = self.path.read_bytes()
        self.off = 0

    def unpack(self, fmt: str, what: str):
        size = struct.calcsize("<" + fmt)
        if self.off + size > len(self.buf):
            raise ColmapFormatError(
                f"{self.path}: truncated or corrupt while reading {what} "
                f"(need {size} bytes at offset {self.off}, file has {len(self.buf)})")
        vals = struct.unpack_from("<" + fmt, self.buf, self.off)
        self.off += size
        return vals

    def array(self, dtype, count: int, what: str) -> np.ndarray:
        dt = np.dtype(dtype).newbyteorder("<")
        size = dt.itemsize * count
        if count < 0 or self.off + size > len(self.buf):
            raise ColmapFormatError(
                f"{self.path}: truncated or corrupt while reading {what} "
                f"({count} x {dt.itemsize} bytes at offset {self.off}, file has {len(self.buf)})")
        out = np.frombuffer(self.buf, dtype=dt, count=count, offset=self.off).copy()
        self.off += size
        return out

    def cstring(self, what: str) -> str:
        end = self.buf.find(b"\x00", self.off)
        if end < 0:
            raise ColmapFormatError(f"{self.path}: truncated or corrupt while reading {what} (no terminating NUL)")
        raw = self.buf[self.off:end]
        self.off = end + 1
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise ColmapFormatError(f"{self.path}: corrupt {what} (not UTF-8: {raw[:40]!r})") from e

    def expect_end(self) -> None:
        if self.off != len(self.buf):
            raise ColmapFormatError(
                f"{self.path}: {len(self.buf) - self.off} unexpected trailing bytes after the last record "
                "(corrupt count field?)")

    def count(self, what: str, min_record_bytes: int) -> int:
        """A uint64 record count, sanity-checked against the bytes left (catches garbage headers)."""
        (n,) = self.unpack("Q", what)
        left = len(self.buf) - self.off
        if n * min_record_bytes > left:
            raise ColmapFormatError(f"{self.path}: truncated or corrupt: {what} = {n} but only {left} bytes follow")
        return int(n)


# --------------------------------------------------------------------------- cameras


def read_cameras_bin(path) -> dict[int, ColmapCamera]:
    r = _BinReader(path)
    n = r.count("num_cameras", 24)
    cams: dict[int, ColmapCamera] = {}
    for i in range(n):
        cam_id, model_id, w, h = r.unpack("iiQQ", f"camera {i} header (camera_id, model_id, width, height)")
        if model_id not in CAMERA_MODELS:
            raise ColmapFormatError(f"{r.path}: camera {cam_id}: unknown model_id {model_id}")
        m = CAMERA_MODELS[model_id]
        params = r.array(np.float64, m.num_params, f"camera {cam_id} params ({m.name})")
        cams[cam_id] = ColmapCamera(cam_id, m.name, int(w), int(h), params)
    r.expect_end()
    return cams


def write_cameras_bin(path, cameras: dict[int, ColmapCamera] | list[ColmapCamera]) -> None:
    cams = list(cameras.values()) if isinstance(cameras, dict) else list(cameras)
    parts = [struct.pack("<Q", len(cams))]
    for c in cams:
        m = camera_model(c.model)
        params = np.asarray(c.params, dtype="<f8").ravel()
        if params.size != m.num_params:
            raise ValueError(f"camera {c.camera_id}: {m.name} needs {m.num_params} params, got {params.size}")
        parts.append(struct.pack("<iiQQ", c.camera_id, m.model_id, c.width, c.height))
        parts.append(params.tobytes())
    _write_bytes(path, b"".join(parts))


# --------------------------------------------------------------------------- images


def read_images_bin(path) -> dict[int, ColmapImage]:
    r = _BinReader(path)
    n = r.count("num_reg_images", 73)
    imgs: dict[int, ColmapImage] = {}
    for i in range(n):
        vals = r.unpack("I7dI", f"image {i} header (image_id, qvec, tvec, camera_id)")
        image_id, q, t, cam_id = vals[0], np.array(vals[1:5]), np.array(vals[5:8]), vals[8]
        name = r.cstring(f"image {image_id} name")
        (p,) = r.unpack("Q", f"image {image_id} ({name}) num_points2D")
        rec = r.array(np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")]), int(p), f"image {image_id} ({name}) points2D")
        xys = np.stack([rec["x"], rec["y"]], -1) if p else np.zeros((0, 2))
        imgs[image_id] = ColmapImage(image_id, q, t, cam_id, name, xys, rec["id"].astype(np.int64))
    r.expect_end()
    return imgs


def write_images_bin(path, images) -> None:
    imgs = list(images.values()) if isinstance(images, dict) else list(images)
    parts = [struct.pack("<Q", len(imgs))]
    for im in imgs:
        if "\x00" in im.name:
            raise ValueError(f"image {im.image_id}: name contains NUL")
        parts.append(struct.pack("<I7dI", im.image_id, *np.asarray(im.qvec, float), *np.asarray(im.tvec, float), im.camera_id))
        parts.append(im.name.encode("utf-8") + b"\x00")
        xys = np.asarray(im.xys, dtype=np.float64).reshape(-1, 2)
        ids = np.asarray(im.point3D_ids, dtype=np.int64).reshape(-1)
        if xys.shape[0] != ids.shape[0]:
            raise ValueError(f"image {im.image_id}: {xys.shape[0]} xys but {ids.shape[0]} point3D_ids")
        rec = np.empty(ids.shape[0], dtype=[("x", "<f8"), ("y", "<f8"), ("id", "<i8")])
        rec["x"], rec["y"], rec["id"] = xys[:, 0], xys[:, 1], ids
        parts.append(struct.pack("<Q", ids.shape[0]))
        parts.append(rec.tobytes())
    _write_bytes(path, b"".join(parts))


# --------------------------------------------------------------------------- points3D

_P3D_HEADER = np.dtype([("id", "<u8"), ("xyz", "<f8", 3), ("rgb", "u1", 3), ("error", "<f8"), ("track_len", "<u8")])
_TRACK_EL = np.dtype([("image_id", "<i4"), ("point2D_idx", "<i4")])


def read_points3D_bin(path) -> ColmapPoints3D:
    """Reads the variable-length records with one cheap offset scan, then gathers fields in numpy."""
    r = _BinReader(path)
    n = r.count("num_points3D", _P3D_HEADER.itemsize)
    buf = r.buf
    start = r.off
    hdr = _P3D_HEADER.itemsize  # 43 bytes
    offsets = np.empty(n, dtype=np.int64)
    tlens = np.empty(n, dtype=np.int64)
    off = start
    size = len(buf)
    # Record boundaries depend on every previous track length, so this scan is sequential;
    # it only decodes one integer per point, the fields are gathered vectorised below.
    for i in range(n):
        if off + hdr > size:
            raise ColmapFormatError(f"{r.path}: truncated or corrupt while reading point3D {i} header "
                                    f"(offset {off}, file has {size} bytes)")
        L = int.from_bytes(buf[off + hdr - 8:off + hdr], "little")
        if off + hdr + 8 * L > size:
            raise ColmapFormatError(f"{r.path}: truncated or corrupt while reading point3D {i} track "
                                    f"(track_length={L} at offset {off}, file has {size} bytes)")
        offsets[i] = off
        tlens[i] = L
        off += hdr + 8 * L
    if off != size:
        raise ColmapFormatError(f"{r.path}: {size - off} unexpected trailing bytes after the last point3D")
    raw = np.frombuffer(buf, dtype=np.uint8)
    heads = raw[offsets[:, None] + np.arange(hdr)[None, :]].copy().view(_P3D_HEADER).reshape(n)
    track_offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(tlens, out=track_offsets[1:])
    T = int(track_offsets[-1])
    # byte position of every track element: record start + header + 8 * (index within the track)
    el_rec = np.repeat(np.arange(n), tlens)
    el_pos = offsets[el_rec] + hdr + 8 * (np.arange(T) - track_offsets[el_rec])
    tracks = raw[el_pos[:, None] + np.arange(8)[None, :]].copy().view(_TRACK_EL).reshape(T) if T else np.zeros(0, _TRACK_EL)
    return ColmapPoints3D(
        ids=heads["id"].astype(np.int64), xyz=heads["xyz"].astype(np.float64), rgb=heads["rgb"].astype(np.uint8),
        error=heads["error"].astype(np.float64), track_offsets=track_offsets,
        track_image_ids=tracks["image_id"].astype(np.int32), track_point2D_idxs=tracks["point2D_idx"].astype(np.int32))


def write_points3D_bin(path, pts: ColmapPoints3D) -> None:
    n = len(pts)
    tlens = np.diff(np.asarray(pts.track_offsets, dtype=np.int64))
    if tlens.shape[0] != n:
        raise ValueError(f"track_offsets must have {n + 1} entries, got {len(pts.track_offsets)}")
    heads = np.empty(n, dtype=_P3D_HEADER)
    heads["id"], heads["xyz"], heads["rgb"] = pts.ids, pts.xyz, pts.rgb
    heads["error"], heads["track_len"] = pts.error, tlens
    tracks = np.empty(int(tlens.sum()), dtype=_TRACK_EL)
    tracks["image_id"], tracks["point2D_idx"] = pts.track_image_ids, pts.track_point2D_idxs
    # interleave fixed headers and variable tracks: build one byte buffer and scatter both in
    rec_sizes = _P3D_HEADER.itemsize + 8 * tlens
    starts = np.zeros(n, dtype=np.int64)
    if n:
        np.cumsum(rec_sizes[:-1], out=starts[1:])
    out = np.empty(8 + int(rec_sizes.sum()), dtype=np.uint8)
    out[:8] = np.frombuffer(struct.pack("<Q", n), np.uint8)
    hdr = _P3D_HEADER.itemsize
    out[(8 + starts)[:, None] + np.arange(hdr)[None, :]] = heads.view(np.uint8).reshape(n, hdr)
    if tracks.size:
        t_off = np.asarray(pts.track_offsets, np.int64)
        el_rec = np.repeat(np.arange(n), tlens)
        el_pos = 8 + starts[el_rec] + hdr + 8 * (np.arange(tracks.size) - t_off[el_rec])
        out[el_pos[:, None] + np.arange(8)[None, :]] = tracks.view(np.uint8).reshape(-1, 8)
    _write_bytes(path, out.tobytes())


# --------------------------------------------------------------------------- whole model


def detect_model_ext(model_dir) -> str:
    """'.bin' if `cameras.bin`+`images.bin` exist, else '.txt' if the text pair exists, else error."""
    d = Path(model_dir)
    for ext in (".bin", ".txt"):
        if (d / f"cameras{ext}").is_file() and (d / f"images{ext}").is_file():
            return ext
    raise ColmapFormatError(f"{d}: no COLMAP model (need cameras.bin+images.bin or cameras.txt+images.txt)")


def read_model(model_dir, ext: str | None = None, *, require_points: bool = False) -> ColmapModel:
    """Read `cameras/images/points3D` from `model_dir` (`.bin` preferred); points3D is optional
    unless `require_points` (Wanderland's metric cloud comes from `raw_pcd.ply`, not from SfM)."""
    d = Path(model_dir)
    ext = ext or detect_model_ext(d)
    rc, ri, rp = (read_cameras_bin, read_images_bin, read_points3D_bin) if ext == ".bin" else \
        (read_cameras_txt, read_images_txt, read_points3D_txt)
    cams, imgs = rc(d / f"cameras{ext}"), ri(d / f"images{ext}")
    p = d / f"points3D{ext}"
    if p.is_file():
        pts = rp(p)
    elif require_points:
        raise ColmapFormatError(f"{p}: file not found")
    else:
        pts = ColmapPoints3D.empty()
    for im in imgs.values():
        if im.camera_id not in cams:
            raise ColmapFormatError(f"{d / ('images' + ext)}: image {im.image_id} ({im.name}) field camera_id = "
                                    f"{im.camera_id} is not in cameras{ext} (has {sorted(cams)[:10]})")
    return ColmapModel(cams, imgs, pts)


def write_model(model_dir, model: ColmapModel, ext: str = ".bin") -> None:
    d = Path(model_dir)
    d.mkdir(parents=True, exist_ok=True)
    if ext == ".bin":
        write_cameras_bin(d / "cameras.bin", model.cameras)
        write_images_bin(d / "images.bin", model.images)
        write_points3D_bin(d / "points3D.bin", model.points3D)
    elif ext == ".txt":
        write_cameras_txt(d / "cameras.txt", model.cameras)
        write_images_txt(d / "images.txt", model.images)
        write_points3D_txt(d / "points3D.txt", model.points3D)
    else:
        raise ValueError(f"ext must be '.bin' or '.txt', got {ext!r}")


def _write_bytes(path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
