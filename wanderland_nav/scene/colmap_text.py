"""COLMAP text-format (`.txt`) readers and writers: `cameras.txt`, `images.txt`, `points3D.txt`.

The data classes come from `scene.colmap_types`; `scene.colmap` (the binary format and whole models)
re-exports the readers and writers here. Formats and error contract are those documented in `scene.colmap`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.scene.colmap_types import (
    ColmapCamera,
    ColmapFormatError,
    ColmapImage,
    ColmapPoints3D,
    camera_model,
)


def _text_lines(path: Path):
    """Yield `(line_number, stripped_line)` for non-comment lines; error if the file is missing."""
    path = Path(path)
    if not path.is_file():
        raise ColmapFormatError(f"{path}: file not found")
    with open(path, encoding="utf-8") as f:
        for ln, line in enumerate(f, 1):
            s = line.strip()
            if s.startswith("#"):
                continue
            yield ln, s


def _parse_numbers(path, ln, tokens, conv, what):
    try:
        return [conv(t) for t in tokens]
    except ValueError as e:
        raise ColmapFormatError(f"{path}:{ln}: cannot parse {what} from {tokens!r}") from e


def read_cameras_txt(path) -> dict[int, ColmapCamera]:
    path = Path(path)
    cams: dict[int, ColmapCamera] = {}
    for ln, s in _text_lines(path):
        if not s:
            continue
        tok = s.split()
        if len(tok) < 4:
            raise ColmapFormatError(f"{path}:{ln}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got {s!r}")
        try:
            m = camera_model(tok[1])
        except KeyError as e:
            raise ColmapFormatError(f"{path}:{ln}: field MODEL: {e.args[0]}") from None
        cam_id, w, h = _parse_numbers(path, ln, [tok[0], tok[2], tok[3]], int, "CAMERA_ID/WIDTH/HEIGHT")
        params = np.asarray(_parse_numbers(path, ln, tok[4:], float, "PARAMS"), dtype=np.float64)
        if params.size != m.num_params:
            raise ColmapFormatError(
                f"{path}:{ln}: field PARAMS: {m.name} needs {m.num_params} params {m.param_names}, got {params.size}")
        cams[cam_id] = ColmapCamera(cam_id, m.name, w, h, params)
    return cams


def write_cameras_txt(path, cameras) -> None:
    cams = list(cameras.values()) if isinstance(cameras, dict) else list(cameras)
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(cams)}"]
    for c in cams:
        m = camera_model(c.model)
        params = np.asarray(c.params, dtype=np.float64).ravel()
        if params.size != m.num_params:
            raise ValueError(f"camera {c.camera_id}: {m.name} needs {m.num_params} params, got {params.size}")
        lines.append(" ".join([str(c.camera_id), m.name, str(c.width), str(c.height)] + [repr(float(p)) for p in params]))
    _write_text(path, "\n".join(lines) + "\n")


def read_images_txt(path) -> dict[int, ColmapImage]:
    """Two lines per image: the pose line and the (possibly empty) POINTS2D line."""
    path = Path(path)
    if not path.is_file():
        raise ColmapFormatError(f"{path}: file not found")
    with open(path, encoding="utf-8") as f:
        raw = [(ln, line.rstrip("\n").strip()) for ln, line in enumerate(f, 1)]
    lines = [(ln, s) for ln, s in raw if not s.startswith("#")]
    # drop trailing empty lines (a model with no images, or a final newline)
    while lines and not lines[-1][1]:
        lines.pop()
    imgs: dict[int, ColmapImage] = {}
    i = 0
    while i < len(lines):
        ln, s = lines[i]
        if not s:  # stray blank line between records
            i += 1
            continue
        tok = s.split()
        if len(tok) < 10:
            raise ColmapFormatError(
                f"{path}:{ln}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {s!r}")
        image_id = _parse_numbers(path, ln, tok[:1], int, "IMAGE_ID")[0]
        qt = np.asarray(_parse_numbers(path, ln, tok[1:8], float, "QW QX QY QZ TX TY TZ"))
        cam_id = _parse_numbers(path, ln, tok[8:9], int, "CAMERA_ID")[0]
        name = " ".join(tok[9:])
        pts = lines[i + 1][1] if i + 1 < len(lines) else ""
        pln = lines[i + 1][0] if i + 1 < len(lines) else ln + 1
        vals = pts.split()
        if len(vals) % 3:
            raise ColmapFormatError(f"{path}:{pln}: field POINTS2D of image {image_id} ({name}): "
                                    f"{len(vals)} values is not a multiple of 3 (X Y POINT3D_ID)")
        arr = np.asarray(_parse_numbers(path, pln, vals, float, "POINTS2D"), dtype=np.float64).reshape(-1, 3)
        imgs[image_id] = ColmapImage(image_id, qt[:4], qt[4:], cam_id, name, arr[:, :2].copy(), arr[:, 2].astype(np.int64))
        i += 2
    return imgs


def write_images_txt(path, images) -> None:
    imgs = list(images.values()) if isinstance(images, dict) else list(images)
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(imgs)}"]
    for im in imgs:
        vals = [repr(float(v)) for v in (*np.asarray(im.qvec, float), *np.asarray(im.tvec, float))]
        lines.append(" ".join([str(im.image_id), *vals, str(im.camera_id), im.name]))
        xys = np.asarray(im.xys, dtype=np.float64).reshape(-1, 2)
        ids = np.asarray(im.point3D_ids, dtype=np.int64).reshape(-1)
        lines.append(" ".join(f"{x!r} {y!r} {int(p)}" for (x, y), p in zip(xys.tolist(), ids.tolist())))
    _write_text(path, "\n".join(lines) + "\n")


def read_points3D_txt(path) -> ColmapPoints3D:
    path = Path(path)
    ids, xyz, rgb, err, tlen, tim, tpt = [], [], [], [], [], [], []
    for ln, s in _text_lines(path):
        if not s:
            continue
        tok = s.split()
        if len(tok) < 8 or (len(tok) - 8) % 2:
            raise ColmapFormatError(
                f"{path}:{ln}: expected POINT3D_ID X Y Z R G B ERROR TRACK[] (pairs), got {len(tok)} values")
        ids.append(_parse_numbers(path, ln, tok[:1], int, "POINT3D_ID")[0])
        xyz.append(_parse_numbers(path, ln, tok[1:4], float, "X Y Z"))
        c = _parse_numbers(path, ln, tok[4:7], int, "R G B")
        if any(v < 0 or v > 255 for v in c):
            raise ColmapFormatError(f"{path}:{ln}: field R G B out of range 0..255: {c}")
        rgb.append(c)
        err.append(_parse_numbers(path, ln, tok[7:8], float, "ERROR")[0])
        tr = _parse_numbers(path, ln, tok[8:], int, "TRACK")
        tlen.append(len(tr) // 2)
        tim.extend(tr[0::2])
        tpt.extend(tr[1::2])
    offs = np.zeros(len(ids) + 1, dtype=np.int64)
    np.cumsum(np.asarray(tlen, dtype=np.int64), out=offs[1:])
    return ColmapPoints3D(np.asarray(ids, np.int64), np.asarray(xyz, np.float64).reshape(-1, 3),
                          np.asarray(rgb, np.uint8).reshape(-1, 3), np.asarray(err, np.float64), offs,
                          np.asarray(tim, np.int32), np.asarray(tpt, np.int32))


def write_points3D_txt(path, pts: ColmapPoints3D) -> None:
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(pts)}"]
    offs = np.asarray(pts.track_offsets, np.int64)
    for i in range(len(pts)):
        a, b = offs[i], offs[i + 1]
        track = " ".join(f"{int(im)} {int(p)}" for im, p in zip(pts.track_image_ids[a:b], pts.track_point2D_idxs[a:b]))
        x, y, z = (repr(float(v)) for v in pts.xyz[i])
        r, g, bl = (int(v) for v in pts.rgb[i])
        lines.append(f"{int(pts.ids[i])} {x} {y} {z} {r} {g} {bl} {float(pts.error[i])!r} {track}".rstrip())
    _write_text(path, "\n".join(lines) + "\n")


def _write_text(path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
