"""Readers for the JSON side files of a scene folder: `transforms.json` and `scene_meta.json`.

`transforms.json` follows the nerfstudio layout Wanderland ships for its fisheye captures:
global (or per-frame) intrinsics `fl_x, fl_y, cx, cy, w, h, k1..k4`, a `camera_model`
(`OPENCV_FISHEYE` / `OPENCV` / `PINHOLE`), and `frames[{file_path, transform_matrix}]` whose
poses are camera-to-world with **OpenGL** camera axes (x right, y up, z back) in a world that
nerfstudio may have re-oriented (`applied_transform`). We convert to OpenCV axes and undo
`applied_transform` so the poses land in the COLMAP/scene frame.

`scene_meta.json` (ARCHITECTURE.md) carries the up axis, the indoor/outdoor tag and nav-frame
indoor polygons; every field is validated with an error that names the file and the field.
"""

from __future__ import annotations

import difflib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wanderland_nav.geometry import parse_up_axis, validate_rigid
from wanderland_nav.scene.types import SceneFormatError

# OpenGL camera axes -> OpenCV camera axes (flip y and z), applied on the right of world_from_cam.
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
FISHEYE_NAMES = {"OPENCV_FISHEYE", "FISHEYE", "EQUIDISTANT", "KANNALA_BRANDT"}
ENVIRONMENTS = ("indoor", "outdoor", "mixed")


def _load_json(path: Path) -> dict:
    if not path.is_file():
        raise SceneFormatError(f"{path}: file not found")
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SceneFormatError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(obj, dict):
        raise SceneFormatError(f"{path}: top level must be an object, got {type(obj).__name__}")
    return obj


def _num(path, obj: dict, key: str, where: str, default=None, required=False) -> float | None:
    if key not in obj:
        if required:
            raise SceneFormatError(f"{path}: {where} missing field '{key}'")
        return default
    v = obj[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise SceneFormatError(f"{path}: {where} field '{key}' must be a finite number, got {v!r}")
    return float(v)


@dataclass
class FrameIntrinsics:
    """Intrinsics for one frame: `K [3,3]`, `distortion [4]` (k1..k4 or k1,k2,p1,p2), size, model."""

    K: np.ndarray
    distortion: np.ndarray
    width: int | None
    height: int | None
    camera_model: str  # "pinhole" | "fisheye"


@dataclass
class TransformsJson:
    path: Path
    camera_model: str | None  # the file's raw string, e.g. "OPENCV_FISHEYE"
    global_intrinsics: FrameIntrinsics | None
    frames: dict[str, dict] = field(default_factory=dict)  # normalised file_path -> raw frame
    scene_from_json_world: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def is_fisheye(self) -> bool:
        return (self.camera_model or "").upper() in FISHEYE_NAMES

    def intrinsics_for(self, image_name: str) -> FrameIntrinsics | None:
        """Per-frame fields override the global ones (nerfstudio allows both)."""
        fr = self.frames.get(_norm_name(image_name)) or self.frames.get(_stem_key(image_name))
        if fr is None or not any(k in fr for k in ("fl_x", "fl_y", "cx", "cy")):
            return self.global_intrinsics
        base = {} if self.global_intrinsics is None else _intr_to_dict(self.global_intrinsics)
        merged = {**base, **{k: fr[k] for k in fr if k in _INTR_KEYS}}
        return _parse_intrinsics(self.path, merged, f"frame '{fr.get('file_path')}'", self.camera_model, required=True)

    def world_from_cam(self, image_name: str) -> np.ndarray | None:
        """OpenCV-axes camera-to-world `[4,4]` in the scene (COLMAP) frame, or None if not listed."""
        fr = self.frames.get(_norm_name(image_name)) or self.frames.get(_stem_key(image_name))
        if fr is None:
            return None
        T = np.asarray(fr["transform_matrix"], dtype=np.float64)
        return self.scene_from_json_world @ T @ GL_TO_CV


_INTR_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "k3", "k4", "p1", "p2")


def _intr_to_dict(fi: FrameIntrinsics) -> dict:
    d = {"fl_x": fi.K[0, 0], "fl_y": fi.K[1, 1], "cx": fi.K[0, 2], "cy": fi.K[1, 2]}
    if fi.width is not None:
        d["w"], d["h"] = fi.width, fi.height
    if fi.camera_model == "fisheye":
        d.update(zip(("k1", "k2", "k3", "k4"), fi.distortion.tolist()))
    else:
        d.update(zip(("k1", "k2", "p1", "p2"), fi.distortion.tolist()))
    return d


def _parse_intrinsics(path, obj: dict, where: str, model: str | None, required: bool) -> FrameIntrinsics | None:
    if not required and not any(k in obj for k in ("fl_x", "fl_y", "cx", "cy")):
        return None
    fx = _num(path, obj, "fl_x", where, required=True)
    fy = _num(path, obj, "fl_y", where, default=fx)
    cx = _num(path, obj, "cx", where, required=True)
    cy = _num(path, obj, "cy", where, required=True)
    if fx <= 0 or fy <= 0:
        raise SceneFormatError(f"{path}: {where} focal length must be positive (fl_x={fx}, fl_y={fy})")
    w, h = _num(path, obj, "w", where), _num(path, obj, "h", where)
    fisheye = (model or "").upper() in FISHEYE_NAMES
    keys = ("k1", "k2", "k3", "k4") if fisheye else ("k1", "k2", "p1", "p2")
    dist = np.array([_num(path, obj, k, where, default=0.0) for k in keys])
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return FrameIntrinsics(K, dist, None if w is None else int(w), None if h is None else int(h),
                           "fisheye" if fisheye else "pinhole")


def _norm_name(name: str) -> str:
    """'./images/a/b.jpg' and 'a/b.jpg' both -> 'a/b.jpg' (transforms.json paths include 'images/')."""
    s = str(name).replace("\\", "/")
    while s.startswith("./"):
        s = s[2:]
    s = s.lstrip("/")
    for prefix in ("images/", "images_fisheye/", "fisheye/"):
        if s.startswith(prefix):
            s = s[len(prefix):]
    return s


def _stem_key(name: str) -> str:
    s = _norm_name(name)
    return "stem:" + s.rsplit(".", 1)[0]



def _rigid_field(value, what: str) -> np.ndarray:
    """A JSON pose field (4x4, or 3x4 without the last row) as a validated rigid 4x4, else SceneFormatError."""
    T = np.asarray(value, dtype=np.float64)
    if T.shape == (3, 4):
        T = np.vstack([T, [0, 0, 0, 1]])
    try:
        validate_rigid(T, what=what)
    except ValueError as e:
        raise SceneFormatError(str(e)) from None
    return T

def read_transforms_json(path) -> TransformsJson:
    path = Path(path)
    obj = _load_json(path)
    model = obj.get("camera_model")
    if model is not None and not isinstance(model, str):
        raise SceneFormatError(f"{path}: field 'camera_model' must be a string, got {model!r}")
    glob = _parse_intrinsics(path, obj, "top level", model, required=False)
    frames_raw = obj.get("frames", [])
    if not isinstance(frames_raw, list):
        raise SceneFormatError(f"{path}: field 'frames' must be a list")
    frames: dict[str, dict] = {}
    for i, fr in enumerate(frames_raw):
        if not isinstance(fr, dict) or not isinstance(fr.get("file_path"), str):
            raise SceneFormatError(f"{path}: frames[{i}] needs a string field 'file_path'")
        if "transform_matrix" in fr:
            T = _rigid_field(fr["transform_matrix"], f"{path}: frames[{i}] ('{fr['file_path']}') field transform_matrix")
            fr = {**fr, "transform_matrix": T}
        frames[_norm_name(fr["file_path"])] = fr
        frames.setdefault(_stem_key(fr["file_path"]), fr)
    S = np.eye(4)
    if "applied_transform" in obj:
        A = _rigid_field(obj["applied_transform"], f"{path}: field applied_transform")
        S = np.linalg.inv(A)  # json_world = A @ scene  ->  scene = A^-1 @ json_world
    return TransformsJson(path, model, glob, frames, S)


# --------------------------------------------------------------------------- scene_meta.json


@dataclass
class SceneMeta:
    path: Path
    name: str | None
    up_axis: str | None
    environment: str | None
    indoor_regions: list[dict]
    raw: dict


#: every top-level `scene_meta.json` key -> (JSON types it may have, what it is). A key not here is refused with
#: the nearest known one: a misspelt `lidar_registerd` would otherwise be ignored and the scene load as if unset
META_SCHEMA: dict[str, tuple[tuple[type, ...], str]] = {
    "version": ((str,), "'v1' or 'v2' (default: from the files present)"),
    "name": ((str,), "the scene's name (default: the folder name)"),
    "up_axis": ((str,), "the scene frame's up axis, e.g. '+z' or '-y'"),
    "environment": ((str,), "one of " + ", ".join(ENVIRONMENTS)),
    "indoor_regions": ((list,), "nav-frame polygons [{polygon_xy, z_min, z_max}]"),
    "lidar_registered": ((bool,), "true: the lidar/ files are already in one world frame (no poses.txt)"),
    "lidar_min_range": ((int, float), "metres; returns closer to the sensor are the capture platform"),
    "lidar_max_pose_jump": ((int, float), "metres; consecutive lidar/poses.txt poses further apart are refused"),
    "lidar_splat": ((dict,), "written by the LiDAR splat builder"),
    "generator": ((dict,), "written by the procedural scene generators (demo, district)"),
    "episode_sampler": ((dict,), "episodes.sampler.SamplerSettings fields this scene's episodes use "
                                 "(unless generator.scene_sampler=false)"),
    "degradation": ((dict,), "written by the degraded-scene builder"),
    "notes": ((str, list, dict), "free-form, never read"),
}
_REGION_KEYS = ("polygon_xy", "z_min", "z_max", "name")


def _unknown_keys(path: Path, obj: dict, known, where: str) -> None:
    for key in obj:
        if key not in known:
            near = difflib.get_close_matches(str(key), list(known), n=1, cutoff=0.6)
            hint = f"did you mean '{near[0]}'? " if near else ""
            raise SceneFormatError(f"{path}: {where}unknown field '{key}' ({hint}known: {', '.join(known)}; "
                                   "free-form text goes under 'notes')")


def _typed(path: Path, obj: dict) -> None:
    for key, (types, what) in META_SCHEMA.items():
        v = obj.get(key)
        # bool is an int in Python: a number field must refuse true/false, a flag must refuse "false"
        if v is not None and (not isinstance(v, types) or (isinstance(v, bool) and bool not in types)):
            raise SceneFormatError(f"{path}: field '{key}' must be {' or '.join(dict.fromkeys(_JSON_NAMES[t] for t in types))} "
                                   f"({what}), got {json.dumps(v)}")


_JSON_NAMES = {str: "a string", bool: "true or false", int: "a number", float: "a number", list: "a list",
               dict: "an object"}


def read_scene_meta(path) -> SceneMeta:
    """`scene_meta.json` -> SceneMeta; unknown keys (with the nearest known one) and wrong types are refused."""
    path = Path(path)
    obj = _load_json(path)
    _unknown_keys(path, obj, META_SCHEMA, "")
    _typed(path, obj)
    up = obj.get("up_axis")
    if up is not None:
        try:
            up = parse_up_axis(up, source=f"{path}: field up_axis")
        except ValueError as e:
            raise SceneFormatError(str(e)) from None
    env = obj.get("environment")
    if env is not None and env not in ENVIRONMENTS:
        raise SceneFormatError(f"{path}: field environment must be one of {ENVIRONMENTS}, got {env!r}")
    regions = obj.get("indoor_regions", [])
    clean = []
    for i, reg in enumerate(regions):
        where = f"{path}: indoor_regions[{i}]"
        if not isinstance(reg, dict) or "polygon_xy" not in reg:
            raise SceneFormatError(f"{where} needs field 'polygon_xy'")
        _unknown_keys(path, reg, _REGION_KEYS, f"indoor_regions[{i}]: ")
        try:
            poly = np.asarray(reg["polygon_xy"], dtype=np.float64)
        except (TypeError, ValueError):
            raise SceneFormatError(f"{where} field polygon_xy must be a list of [x, y]") from None
        if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3 or not np.isfinite(poly).all():
            raise SceneFormatError(f"{where} field polygon_xy must hold >= 3 finite [x, y] points, got shape {poly.shape}")
        zmin = _num(path, reg, "z_min", f"indoor_regions[{i}]", default=-np.inf) if "z_min" in reg else -np.inf
        zmax = _num(path, reg, "z_max", f"indoor_regions[{i}]", default=np.inf) if "z_max" in reg else np.inf
        if zmin >= zmax:
            raise SceneFormatError(f"{where}: z_min ({zmin}) must be below z_max ({zmax})")
        clean.append({**reg, "polygon_xy": poly.tolist(), "z_min": zmin, "z_max": zmax})
    return SceneMeta(path, obj.get("name"), up, env, clean, obj)
