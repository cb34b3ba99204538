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

The text-format (`.txt`) readers and writers live in `scene.colmap_text` and are re-exported here.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError


log = logging.getLogger(__name__)


class ColmapFormatError(WanderlandInputError):
    """A COLMAP file is missing, truncated or malformed (message names file and field)."""


@dataclass(frozen=True)
class CameraModel:
    model_id: int
    name: str
    num_params: int
    param_names: tuple[str, ...]


# Every model COLMAP defines (colmap/src/colmap/sensor/models.h), id -> layout.
_MODELS = [
    CameraModel(0, "SIMPLE_PINHOLE", 3, ("f", "cx", "cy")),
    CameraModel(1, "PINHOLE", 4, ("fx", "fy", "cx", "cy")),
    CameraModel(2, "SIMPLE_RADIAL", 4, ("f", "cx", "cy", "k")),
    CameraModel(3, "RADIAL", 5, ("f", "cx", "cy", "k1", "k2")),
    CameraModel(4, "OPENCV", 8, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")),
    CameraModel(5, "OPENCV_FISHEYE", 8, ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")),
    CameraModel(6, "FULL_OPENCV", 12, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")),
    CameraModel(7, "FOV", 5, ("fx", "fy", "cx", "cy", "omega")),
    CameraModel(8, "SIMPLE_RADIAL_FISHEYE", 4, ("f", "cx", "cy", "k")),
    CameraModel(9, "RADIAL_FISHEYE", 5, ("f", "cx", "cy", "k1", "k2")),
    CameraModel(10, "THIN_PRISM_FISHEYE", 12, ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1")),
    CameraModel(11, "RAD_TAN_THIN_PRISM_FISHEYE", 16,
                ("fx", "fy", "cx", "cy", "k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1", "s2", "s3")),
]
CAMERA_MODELS: dict[int, CameraModel] = {m.model_id: m for m in _MODELS}
_WARNED_DROPPED: set[tuple[str, int]] = set()  # (model, camera id) already warned about unmodelled distortion


def _num_distortion(m: "CameraModel") -> int:
    """How many of a model's parameters are distortion terms (all after f / fx, fy, cx, cy)."""
    return m.num_params - (3 if m.param_names[0] == "f" else 4)


CAMERA_MODELS_BY_NAME: dict[str, CameraModel] = {m.name: m for m in _MODELS}
FISHEYE_MODELS = {"OPENCV_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "THIN_PRISM_FISHEYE",
                  "RAD_TAN_THIN_PRISM_FISHEYE", "FOV"}


def camera_model(key: int | str) -> CameraModel:
    """Look a model up by COLMAP id or name (case-insensitive)."""
    if isinstance(key, str):
        m = CAMERA_MODELS_BY_NAME.get(key.strip().upper())
    else:
        m = CAMERA_MODELS.get(int(key))
    if m is None:
        raise KeyError(f"unknown COLMAP camera model {key!r}; known: {sorted(CAMERA_MODELS_BY_NAME)}")
    return m


# --------------------------------------------------------------------------- data classes


@dataclass
class ColmapCamera:
    camera_id: int
    model: str  # COLMAP model name, e.g. "PINHOLE"
    width: int
    height: int
    params: np.ndarray  # [num_params] float64, in CameraModel.param_names order

    def intrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """`(K [3,3], distortion [4])` in the (pinhole|OpenCV-fisheye) convention the Scene uses.

        distortion holds k1..k4 for fisheye models and (k1, k2, p1, p2) for OPENCV; models with
        more terms keep their first four, which is what a renderer without them can honour.
        """
        m = camera_model(self.model)
        p = dict(zip(m.param_names, np.asarray(self.params, dtype=np.float64)))
        fx = p.get("fx", p.get("f"))
        fy = p.get("fy", p.get("f"))
        K = np.array([[fx, 0.0, p["cx"]], [0.0, fy, p["cy"]], [0.0, 0.0, 1.0]])
        if m.name in ("SIMPLE_RADIAL", "SIMPLE_RADIAL_FISHEYE"):
            d = [p["k"], 0.0, 0.0, 0.0]
        elif m.name in ("RADIAL", "RADIAL_FISHEYE"):
            d = [p["k1"], p["k2"], 0.0, 0.0]
        elif m.name == "OPENCV":
            d = [p["k1"], p["k2"], p["p1"], p["p2"]]
        elif m.name == "FULL_OPENCV":  # radial-tangential like OPENCV (was k1, k2, k3, k4: read as p1, p2)
            d = [p["k1"], p["k2"], p["p1"], p["p2"]]
        elif m.name in ("OPENCV_FISHEYE", "THIN_PRISM_FISHEYE"):
            d = [p["k1"], p["k2"], p["k3"], p["k4"]]
        elif m.name == "RAD_TAN_THIN_PRISM_FISHEYE":
            d = [p["k0"], p["k1"], p["k2"], p["k3"]]
        else:
            d = [0.0] * 4
        kept = {"OPENCV": ("k1", "k2", "p1", "p2"), "FULL_OPENCV": ("k1", "k2", "p1", "p2"),
                "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4"), "THIN_PRISM_FISHEYE": ("k1", "k2", "k3", "k4"),
                "RAD_TAN_THIN_PRISM_FISHEYE": ("k0", "k1", "k2", "k3"), "SIMPLE_RADIAL": ("k",),
                "SIMPLE_RADIAL_FISHEYE": ("k",), "RADIAL": ("k1", "k2"), "RADIAL_FISHEYE": ("k1", "k2")}.get(m.name, ())
        dropped = tuple(n for n in m.param_names[len(m.param_names) - _num_distortion(m):] if n not in kept and p[n] != 0)
        if dropped and (m.name, self.camera_id) not in _WARNED_DROPPED:
            _WARNED_DROPPED.add((m.name, self.camera_id))
            log.warning("COLMAP camera %d (%s): distortion terms %s are not modelled (only %s are): images of "
                        "this camera are undistorted approximately", self.camera_id, m.name, list(dropped),
                        list(kept) or "none")
        return K, np.asarray(d, dtype=np.float64)


@dataclass
class ColmapImage:
    image_id: int
    qvec: np.ndarray  # [4] float64, cam_from_world rotation, wxyz
    tvec: np.ndarray  # [3] float64, cam_from_world translation
    camera_id: int
    name: str
    xys: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # [P,2] float64 pixel coords
    point3D_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # [P] int64, -1 = none

    def cam_from_world(self) -> np.ndarray:
        """`[4,4]` float64 pose as stored by COLMAP."""
        T = np.eye(4)
        T[:3, :3] = qvec_to_rotmat(self.qvec)
        T[:3, 3] = self.tvec
        return T

    def world_from_cam(self) -> np.ndarray:
        """`[4,4]` float64 camera-to-world pose (OpenCV camera axes, world = COLMAP frame)."""
        R = qvec_to_rotmat(self.qvec)
        T = np.eye(4)
        T[:3, :3] = R.T
        T[:3, 3] = -R.T @ np.asarray(self.tvec, dtype=np.float64)
        return T


@dataclass
class ColmapPoints3D:
    """All 3D points as arrays (struct of arrays: a scene has 1e5-1e6 of them).

    Tracks are stored CSR-style: the track of point i is
    `track_image_ids[track_offsets[i]:track_offsets[i+1]]` (and `track_point2D_idxs` likewise).
    """

    ids: np.ndarray  # [N] int64
    xyz: np.ndarray  # [N,3] float64, world (COLMAP) frame
    rgb: np.ndarray  # [N,3] uint8
    error: np.ndarray  # [N] float64 reprojection error (px)
    track_offsets: np.ndarray  # [N+1] int64
    track_image_ids: np.ndarray  # [T] int32
    track_point2D_idxs: np.ndarray  # [T] int32

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    @staticmethod
    def empty() -> "ColmapPoints3D":
        return ColmapPoints3D(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0),
                              np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32))


def qvec_to_rotmat(q) -> np.ndarray:
    """wxyz quaternion `[4]` (normalised here) -> rotation `[3,3]` float64."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"quaternion {q.tolist()} is not finite / has zero norm")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotmat_to_qvec(R) -> np.ndarray:
    """Rotation `[3,3]` -> unit wxyz quaternion `[4]` with w >= 0 (Shepperd's largest-diagonal branch)."""
    m = np.asarray(R, dtype=np.float64)
    tr = np.trace(m)
    cands = np.array([
        [1 + tr, m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]],
        [m[2, 1] - m[1, 2], 1 + m[0, 0] - m[1, 1] - m[2, 2], m[0, 1] + m[1, 0], m[0, 2] + m[2, 0]],
        [m[0, 2] - m[2, 0], m[0, 1] + m[1, 0], 1 - m[0, 0] + m[1, 1] - m[2, 2], m[1, 2] + m[2, 1]],
        [m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1], 1 - m[0, 0] - m[1, 1] + m[2, 2]],
    ])
    q = cands[int(np.argmax([tr, m[0, 0], m[1, 1], m[2, 2]]))]
    q = q / np.linalg.norm(q)
    return -q if q[0] < 0 else q


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


@dataclass
class ColmapModel:
    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points3D: ColmapPoints3D


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
    from wanderland_nav.scene.colmap_text import (
        read_cameras_txt,
        read_images_txt,
        read_points3D_txt,
    )

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
    from wanderland_nav.scene.colmap_text import (
        write_cameras_txt,
        write_images_txt,
        write_points3D_txt,
    )

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


# --------------------------------------------------------------------------- text format (re-exported)

# The `.txt` readers/writers live in `scene.colmap_text` (to keep each module small). They are re-exported
# here lazily (PEP 562) because colmap_text imports this module's data classes: an eager import in
# either direction would fail when the other module is imported first.
_TEXT_EXPORTS = frozenset({"read_cameras_txt", "write_cameras_txt", "read_images_txt", "write_images_txt",
                           "read_points3D_txt", "write_points3D_txt", "_text_lines", "_parse_numbers", "_write_text"})


def __getattr__(name: str):
    if name in _TEXT_EXPORTS:
        import wanderland_nav.scene.colmap_text as text

        value = getattr(text, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | _TEXT_EXPORTS)
