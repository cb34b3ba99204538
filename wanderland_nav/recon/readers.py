"""Read a prediction or ground truth into a `PoseSet`, whatever tool wrote it.

Inputs and their frame conventions (each converted to camera-to-world, OpenCV axes, here):

| input | detected by | stored as | keyed by |
|---|---|---|---|
| COLMAP model (`sparse/0`, `.bin` or `.txt`) | folder with `cameras.*` + `images.*`, or an `images.*` file | **world-to-camera** `qvec` (wxyz), `tvec` | image name |
| Wanderland scene folder | `sparse/`, `raw_pcd.ply`, `scene.ply`, `lidar/` or `scene_meta.json` | via `load_scene` (train + val cameras) | image name |
| nerfstudio / Wanderland `transforms.json` | a `.json` file, or a folder holding only it | **camera-to-world, OpenGL axes** (x right, y up, z back), `applied_transform` undone | `file_path` |
| TUM trajectory (`t x y z qx qy qz qw`) | any other text file | **camera(or IMU)-to-world**, quaternion xyzw | timestamp (s) |

A TUM file that repeats a timestamp (the real fr2/desk ground truth does, stamps rounded to
0.1 ms) keeps the first pose of each stamp, as evo's nearest-stamp search does, and reports how
many it left out (`PoseSet.duplicates_dropped`). Repeated image names are an error.

Image names are normalised as the scene loader does (`./images/a.jpg` -> `a.jpg`) so a COLMAP
prediction matches a transforms.json ground truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from wanderland_nav.geometry import quat_to_rotmat
from wanderland_nav.recon.poses import PoseSet, ReconInputError, from_cam_from_world
from wanderland_nav.scene import colmap as C, load_scene
from wanderland_nav.scene.transforms import _norm_name, read_transforms_json
from wanderland_nav.scene.types import SceneFormatError

_SCENE_MARKERS = ("sparse", "raw_pcd.ply", "scene.ply", "lidar", "scene_meta.json")


def detect_kind(path) -> str:
    """"colmap" | "scene" | "transforms" | "tum" for `path`, or ReconInputError if it is none of them."""
    p = Path(path)
    if p.is_file():
        if p.suffix == ".json":
            return "transforms"
        if p.stem == "images" and p.suffix in (".bin", ".txt"):
            return "colmap"
        return "tum"
    if not p.is_dir():
        raise ReconInputError(f"{p}: no such file or folder")
    if any((p / m).exists() for m in _SCENE_MARKERS):
        return "scene"
    try:
        C.detect_model_ext(p)
        return "colmap"
    except C.ColmapFormatError:
        pass
    if (p / "transforms.json").is_file():
        return "transforms"
    raise ReconInputError(f"{p}: not a COLMAP model (cameras.* + images.*), a scene folder ({', '.join(_SCENE_MARKERS)}) "
                          "or a folder with transforms.json")


def read_poses(path, kind: str = "auto") -> PoseSet:
    """The cameras at `path` as a `PoseSet` (see the module table for what `kind` accepts)."""
    p = Path(path)
    kind = detect_kind(p) if kind == "auto" else kind
    readers = {"colmap": read_colmap, "scene": read_scene, "transforms": read_transforms, "tum": read_tum}
    if kind not in readers:
        raise ValueError(f"kind={kind!r}: expected auto or one of {sorted(readers)}")
    return readers[kind](p)


def read_colmap(path) -> PoseSet:
    """COLMAP `images.{bin,txt}` (a model folder or the file itself): world-to-camera -> camera-to-world."""
    p = Path(path)
    f = p if p.is_file() else p / f"images{C.detect_model_ext(p)}"
    try:
        images = C.read_images_bin(f) if f.suffix == ".bin" else C.read_images_txt(f)
    except C.ColmapFormatError as e:
        raise ReconInputError(str(e)) from None
    ims = sorted(images.values(), key=lambda im: im.image_id)
    q = np.array([im.qvec for im in ims], dtype=np.float64).reshape(-1, 4)  # [N,4] wxyz
    t = np.array([im.tvec for im in ims], dtype=np.float64).reshape(-1, 3)
    _check_finite(f, np.concatenate([q, t], 1), [f"image {im.image_id} ({im.name!r})" for im in ims], "qvec/tvec")
    E = np.tile(np.eye(4), (len(ims), 1, 1))
    E[:, :3, :3] = _quat_wxyz_to_rotmat(f, q, [im.name for im in ims])
    E[:, :3, 3] = t
    return PoseSet(from_cam_from_world(E), str(f), "colmap", names=tuple(_norm_name(im.name) for im in ims))


def read_scene(path) -> PoseSet:
    """A Wanderland scene folder's grounded poses (every camera, train and val split)."""
    try:
        scene = load_scene(path)
    except SceneFormatError as e:
        raise ReconInputError(str(e)) from None
    if not scene.cameras:
        raise ReconInputError(f"{path}: scene has no cameras (no sparse model or transforms.json frames); recon_eval "
                              "scores camera poses and novel views, a LiDAR-only scene (lidar/ + poses.txt) has neither")
    return PoseSet(scene.world_from_cams(), str(path), "scene", names=tuple(_norm_name(c.name) for c in scene.cameras),
                   up_axis=scene.up_axis)


def read_transforms(path) -> PoseSet:
    """transforms.json frames with a `transform_matrix` (camera-to-world, OpenGL axes -> OpenCV)."""
    p = Path(path)
    f = p / "transforms.json" if p.is_dir() else p
    try:
        tj = read_transforms_json(f)
    except SceneFormatError as e:
        raise ReconInputError(str(e)) from None
    names = sorted(k for k, fr in tj.frames.items() if not k.startswith("stem:") and "transform_matrix" in fr)
    if not names:
        raise ReconInputError(f"{f}: field frames has no entry with a transform_matrix")
    return PoseSet(np.stack([tj.world_from_cam(n) for n in names]), str(f), "transforms", names=tuple(names))


def read_tum(path) -> PoseSet:
    """TUM RGB-D trajectory: `timestamp tx ty tz qx qy qz qw` per line, `#` comments; camera-to-world."""
    p = Path(path)
    try:
        rows = np.loadtxt(p, dtype=np.float64, comments="#", ndmin=2)
    except ValueError as e:
        raise ReconInputError(f"{p}: not a TUM trajectory (timestamp tx ty tz qx qy qz qw per line): {e}") from None
    if rows.size == 0:
        raise ReconInputError(f"{p}: no poses")
    if rows.shape[1] != 8:
        raise ReconInputError(f"{p}: TUM lines need 8 numbers (timestamp tx ty tz qx qy qz qw), got {rows.shape[1]}")
    labels = [f"row {i} (stamp {s:.6f})" for i, s in enumerate(rows[:, 0])]
    _check_finite(p, rows[:, 1:], labels, "tx ty tz qx qy qz qw")
    T = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    T[:, :3, :3] = _quat_wxyz_to_rotmat(p, rows[:, [7, 4, 5, 6]], labels)
    T[:, :3, 3] = rows[:, 1:4]
    first = np.sort(np.unique(rows[:, 0], return_index=True)[1])  # first row of every distinct stamp
    return PoseSet(T[first], str(p), "tum", stamps=rows[first, 0], duplicates_dropped=int(rows.shape[0] - first.size))


def _check_finite(path, values: np.ndarray, labels: list[str], fields: str) -> None:
    bad = np.flatnonzero(~np.isfinite(values).all(-1))
    if bad.size:
        raise ReconInputError(f"{path}: {labels[bad[0]]} field {fields} is not finite (NaN/inf; {bad.size} in all)")


def _quat_wxyz_to_rotmat(path, q: np.ndarray, labels: list[str]) -> np.ndarray:
    """`[N,4]` wxyz quaternions (normalised here, as evo does) -> `[N,3,3]`; a zero quaternion is an error."""
    n = np.linalg.norm(q, axis=-1)
    bad = np.flatnonzero(n < 1e-9)
    if bad.size:
        raise ReconInputError(f"{path}: {labels[bad[0]]} has a zero quaternion (no rotation)")
    return quat_to_rotmat(torch.from_numpy(q)).numpy()
