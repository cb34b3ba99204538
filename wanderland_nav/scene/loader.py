"""`load_scene(path, up_axis=None)`: read a Wanderland scene folder (v1 or v2) into a `Scene`.

v1 (COLMAP frame, -y up): `sparse/0/{cameras,images,points3D}.{bin|txt}` (+ `images_val.{bin|txt}`
for the held-out extrapolation path), `images/`, `images_mask/`, `depth/`, `nvs_split/{train,val}.txt`,
`raw_pcd.ply` (the metric LiDAR cloud), `3dgs.ply`, `transforms.json` (fisheye intrinsics),
`episodes.json`. v2 (+z up): `scene.ply` (mesh), `lidar/*.{ply,bin}` (+ optional `lidar/poses.txt`,
KITTI 3x4 world_from_lidar per frame), cameras as in v1 when present.

Up axis precedence: explicit `up_axis` argument > `scene_meta.json` `up_axis` > the layout's
documented convention (v1: "-y", v2: "+z"). The choice and its source are logged and kept in
`Scene.up_axis_source`, so it is never a silent guess.

Every inconsistency (missing folder, corrupt file, NaN / non-orthonormal pose, image named in
images.bin with no file, split file naming an unknown image) raises `SceneFormatError` naming the
file and the field: a scene that half-loads gives wrong collision meshes and wrong episodes.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np

from wanderland_nav.geometry import parse_up_axis, validate_rigid
from wanderland_nav.scene import colmap as C
from wanderland_nav.scene.products import products_dir
from wanderland_nav.scene.types import Camera, Scene, SceneFormatError
from wanderland_nav.scene.pointcloud import (LIDAR_SUFFIXES, PointCloudFormatError, read_ply_points,
                                             read_points_any)
from wanderland_nav.scene.transforms import (TransformsJson, _norm_name, read_scene_meta,
                                             read_transforms_json)

log = logging.getLogger(__name__)

DEFAULT_UP = {"v1": "-y", "v2": "+z"}
_MASK_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".npy")
_DEPTH_EXTS = (".npy", ".png", ".exr", ".tif", ".tiff", ".pfm")
_QUAT_NORM_TOL = 1e-2


#: files whose presence marks a folder as a scene folder (any one of them); extend here for new layouts
def load_scene(path, up_axis: str | None = None) -> Scene:
    """Load the scene folder at `path` (v1 or v2 layout, detected from its files)."""
    root = Path(path)
    if not root.exists():
        raise SceneFormatError(f"{root}: scene folder not found")
    if not root.is_dir():
        raise SceneFormatError(f"{root}: not a folder")
    meta = read_scene_meta(root / "scene_meta.json") if (root / "scene_meta.json").is_file() else None
    version = _detect_version(root, meta)
    up, source = _resolve_up_axis(root, version, meta, up_axis)
    log.info("%s: %s layout, up axis %s (%s)", root, version, up, source)

    tj = read_transforms_json(root / "transforms.json") if (root / "transforms.json").is_file() else None
    cameras = _load_cameras(root, tj)
    lidar_poses, lidar_filter = None, None
    if version == "v1":
        points, colors = _load_v1_points(root)
    else:
        points, colors, lidar_poses, lidar_filter = _load_v2_points(root, meta)

    products = products_dir(root)  # before any computation: a read-only scene's files go to a cache folder

    def opt(name: str) -> Path | None:  # a generated file: where this run writes it first, then beside the scene
        for d in ([products] if products is not None else []) + [root]:
            if (d / name).is_file():
                return d / name
        return None

    return Scene(
        name=(meta.name if meta and meta.name else root.name), root=root, version=version, up_axis=up,
        points=points, colors=colors, cameras=cameras, gaussians_path=opt("3dgs.ply"),
        collision_mesh_path=opt("collision_mesh.ply"), navmesh_path=opt("navmesh.npz"),
        episodes_path=opt("episodes.json"), gt_mesh_path=opt("gt_mesh.ply"),
        environment=meta.environment if meta else None, indoor_regions=meta.indoor_regions if meta else [],
        up_axis_source=source, mesh_path=opt("scene.ply") if version == "v2" else None,
        meta={**(meta.raw if meta else {}), **({"lidar_filter": lidar_filter} if lidar_filter else {})},
        lidar_poses=lidar_poses, products_root=products,
    )


# --------------------------------------------------------------------------- layout / up axis


def _sparse_dir(root: Path) -> Path | None:
    for d in (root / "sparse" / "0", root / "sparse"):
        try:
            C.detect_model_ext(d)
            return d
        except C.ColmapFormatError:
            continue
    return None


def _name_key(p: Path) -> list:
    """Natural order: digit runs compare as numbers, so `2.bin` precedes `10.bin` (KITTI-style numbering
    without zero padding; text order would give scan 10 the pose of scan 2)."""
    return [(0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", p.name) if t]


def visible_files(folder: Path) -> list[Path]:
    """The files in `folder` in natural name order, without hidden ones (`.DS_Store`, macOS AppleDouble `._x.bin`
    copies, which carry a scan's suffix but hold resource forks); none when `folder` is not a folder."""
    if not folder.is_dir():
        return []
    return sorted((p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")), key=_name_key)


def _lidar_files(root: Path) -> list[Path]:
    """Point-cloud files in `lidar/` in natural name order: the order `lidar/poses.txt` lines follow."""
    return [p for p in visible_files(root / "lidar") if p.suffix.lower() in LIDAR_SUFFIXES]


SCENE_LAYOUTS = ("a scene folder holds sparse/0 (COLMAP) or raw_pcd.ply (v1), or scene.ply or point clouds "
                 "in lidar/ (v2)")


def scene_layout(path) -> str | None:
    """"v1", "v2" or None (not a scene folder), from the files present. The one definition every entry
    point uses to decide whether a folder is a scene: v1 has `sparse/0` (COLMAP) or `raw_pcd.ply`; v2 has
    `scene.ply` or point clouds in `lidar/` (`.ply`, KITTI `.bin`, `.las`; a LiDAR-only folder counts)."""
    root = Path(path)
    if not root.is_dir():
        return None
    has_v2 = (root / "scene.ply").is_file() or bool(_lidar_files(root))
    if has_v2 and not (root / "raw_pcd.ply").is_file():
        return "v2"
    if (root / "raw_pcd.ply").is_file() or _sparse_dir(root) is not None:
        return "v1"
    return None


def is_scene_folder(path) -> bool:
    """Whether `load_scene(path)` finds a scene layout there (see `scene_layout`)."""
    return scene_layout(path) is not None


def _detect_version(root: Path, meta) -> str:
    declared = meta.raw.get("version") if meta else None
    if declared is not None:
        if declared not in ("v1", "v2"):
            raise SceneFormatError(f"{meta.path}: field version must be 'v1' or 'v2', got {declared!r}")
        return declared
    version = scene_layout(root)
    if version is None:
        raise SceneFormatError(
            f"{root}: not a Wanderland scene folder: expected sparse/0/{{cameras,images}}.{{bin,txt}} or "
            f"raw_pcd.ply (v1), or scene.ply / lidar/*{{{','.join(LIDAR_SUFFIXES)}}} (v2)")
    return version


def _resolve_up_axis(root: Path, version: str, meta, up_axis: str | None) -> tuple[str, str]:
    if up_axis is not None:
        up = parse_up_axis(up_axis, source="load_scene(up_axis=...)")
        if meta and meta.up_axis and meta.up_axis != up:
            log.warning("%s: up_axis argument %s overrides scene_meta.json up_axis %s", root, up, meta.up_axis)
        return up, "argument"
    if meta and meta.up_axis:
        return meta.up_axis, f"{meta.path.name}"
    return DEFAULT_UP[version], f"{version} layout convention ({'COLMAP frame' if version == 'v1' else 'Z-up'})"


# --------------------------------------------------------------------------- cameras


def _side_of(name: str) -> str | None:
    """'left'/'right' from a path component or name token (rig cameras are named so in captures)."""
    toks = [t for t in _tokens(name.lower())]
    has_l = any(t in ("left", "l", "cam_left", "left_cam") for t in toks)
    has_r = any(t in ("right", "r", "cam_right", "right_cam") for t in toks)
    if has_l != has_r:
        return "left" if has_l else "right"
    return None


def _tokens(s: str) -> list[str]:
    out = []
    for part in s.replace("\\", "/").split("/"):
        stem = part.rsplit(".", 1)[0]
        out.append(stem)
        out.extend(t for t in stem.replace("-", "_").split("_") if t)
    return out


def _file_index(folder: Path, exts: tuple[str, ...]) -> dict[str, Path]:
    """relative path without suffix -> file (first matching extension in `exts` order wins)."""
    idx: dict[str, Path] = {}
    if not folder.is_dir():
        return idx
    rank = {e: i for i, e in enumerate(exts)}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.suffix.lower() in rank:
            key = p.relative_to(folder).with_suffix("").as_posix()
            if key not in idx or rank[p.suffix.lower()] < rank[idx[key].suffix.lower()]:
                idx[key] = p
    return idx


def _load_cameras(root: Path, tj: TransformsJson | None) -> list[Camera]:
    sdir = _sparse_dir(root)
    if sdir is not None:
        return _cameras_from_colmap(root, sdir, tj)
    if tj is not None and any("transform_matrix" in fr for fr in tj.frames.values()):
        return _cameras_from_transforms(root, tj)
    return []


def _find_val_images(sdir: Path, root: Path) -> Path | None:
    for d in (sdir, root):
        for ext in (".bin", ".txt"):
            p = d / f"images_val{ext}"
            if p.is_file():
                return p
    return None


def _check_qvec(path: Path, im: C.ColmapImage) -> None:
    q = np.asarray(im.qvec, dtype=np.float64)
    t = np.asarray(im.tvec, dtype=np.float64)
    if not (np.isfinite(q).all() and np.isfinite(t).all()):
        raise SceneFormatError(f"{path}: image {im.image_id} ({im.name}) field qvec/tvec is not finite "
                               f"(qvec={q.tolist()}, tvec={t.tolist()})")
    n = np.linalg.norm(q)
    if abs(n - 1.0) > _QUAT_NORM_TOL:
        raise SceneFormatError(f"{path}: image {im.image_id} ({im.name}) field qvec has norm {n:.4g}: "
                               "the rotation is not orthonormal (COLMAP stores unit quaternions)")


def _cameras_from_colmap(root: Path, sdir: Path, tj: TransformsJson | None) -> list[Camera]:
    ext = C.detect_model_ext(sdir)
    try:
        model = C.read_model(sdir, ext)
        images_file = sdir / f"images{ext}"
        entries = [(im, images_file, "train") for im in model.images.values()]
        val_file = _find_val_images(sdir, root)
        if val_file is not None:
            val = C.read_images_bin(val_file) if val_file.suffix == ".bin" else C.read_images_txt(val_file)
            for im in val.values():
                if im.camera_id not in model.cameras:
                    raise SceneFormatError(f"{val_file}: image {im.image_id} ({im.name}) field camera_id = "
                                           f"{im.camera_id} is not in {sdir / ('cameras' + ext)}")
            entries += [(im, val_file, "val") for im in val.values()]
    except C.ColmapFormatError as e:
        raise SceneFormatError(str(e)) from None

    seen: dict[str, Path] = {}
    for im, f, _ in entries:
        if im.name in seen:
            raise SceneFormatError(f"{f}: image name {im.name!r} (field name) appears twice "
                                   f"(also in {seen[im.name].name})")
        seen[im.name] = f
    entries.sort(key=lambda e: e[0].name)

    images_dir, mask_idx, depth_idx = root / "images", _file_index(root / "images_mask", _MASK_EXTS), \
        _file_index(root / "depth", _DEPTH_EXTS)
    if not images_dir.is_dir():
        log.warning("%s: no images/ folder: cameras have no image_path", root)
    n_tj = 0
    cams: list[Camera] = []
    missing: list[tuple[str, Path]] = []
    for im, f, split in entries:
        _check_qvec(f, im)
        T = im.world_from_cam()
        try:
            validate_rigid(T, what=f"{f}: image {im.image_id} ({im.name}) field qvec/tvec")
        except ValueError as e:
            raise SceneFormatError(str(e)) from None
        cc = model.cameras[im.camera_id]
        K, dist = cc.intrinsics()
        kind = "fisheye" if cc.model in C.FISHEYE_MODELS else "pinhole"
        width, height = cc.width, cc.height
        if tj is not None and tj.is_fisheye and (tj.frames.get(_norm_name(im.name)) is not None or kind == "fisheye"):
            fi = tj.intrinsics_for(im.name)
            if fi is not None:  # transforms.json's fisheye calibration wins (see module docstring)
                K, dist, kind = fi.K, fi.distortion, "fisheye"
                width, height = fi.width or width, fi.height or height
                n_tj += 1
        img_path = None
        if images_dir.is_dir():
            img_path = images_dir / im.name
            if not img_path.is_file():
                missing.append((im.name, f))
        key = Path(im.name).with_suffix("").as_posix()
        cams.append(Camera(name=im.name, world_from_cam=T, K=K, width=int(width), height=int(height),
                           camera_model=kind, distortion=np.asarray(dist, dtype=np.float64), image_path=img_path,
                           mask_path=mask_idx.get(key), depth_path=depth_idx.get(key), side=_side_of(im.name),
                           split=split))
    if missing:
        name, f = missing[0]
        raise SceneFormatError(f"{f}: field name: {len(missing)} image(s) have no file under {images_dir} "
                               f"(first: {name!r})")
    if n_tj:
        log.info("%s: fisheye intrinsics for %d camera(s) taken from transforms.json", root, n_tj)
    _apply_split_files(root, cams)
    return cams


def _cameras_from_transforms(root: Path, tj: TransformsJson) -> list[Camera]:
    """No COLMAP model: poses and intrinsics from transforms.json frames (converted to OpenCV axes).
    Images live in `images/` (v1) or `fisheye/` (v2 as released); frame paths may carry either prefix."""
    images_dir = next((root / d for d in ("images", "fisheye", "images_fisheye") if (root / d).is_dir()),
                      root / "images")
    mask_idx, depth_idx = _file_index(root / "images_mask", _MASK_EXTS), _file_index(root / "depth", _DEPTH_EXTS)
    cams = []
    frames = sorted({id(fr): fr for fr in tj.frames.values() if "transform_matrix" in fr}.values(),
                    key=lambda fr: fr["file_path"])
    for fr in frames:
        name = _norm_name(fr["file_path"])
        fi = tj.intrinsics_for(name)
        if fi is None or fi.width is None:
            raise SceneFormatError(f"{tj.path}: frame '{fr['file_path']}' has no intrinsics (fl_x, cx, cy, w, h)")
        T = tj.world_from_cam(name)
        img = images_dir / name if images_dir.is_dir() else None
        if img is not None and not img.is_file():
            raise SceneFormatError(f"{tj.path}: frame field file_path {fr['file_path']!r} has no file under {images_dir}")
        key = Path(name).with_suffix("").as_posix()
        cams.append(Camera(name, T, fi.K, fi.width, fi.height, fi.camera_model, fi.distortion, img,
                           mask_idx.get(key), depth_idx.get(key), _side_of(name), "train"))
    _apply_split_files(root, cams)
    return cams


def _apply_split_files(root: Path, cams: list[Camera]) -> None:
    """`nvs_split/{train,val}.txt` name images (full relative name, basename or stem). They win over
    images_val; cameras listed in neither keep their split (images.bin -> train, images_val -> val)."""
    split_dir = root / "nvs_split"
    files = {s: split_dir / f"{s}.txt" for s in ("train", "val") if (split_dir / f"{s}.txt").is_file()}
    if not files:
        return
    by_key: dict[str, list[int]] = {}
    for i, c in enumerate(cams):
        n = _norm_name(c.name)
        for k in {n, n.rsplit("/", 1)[-1], Path(n).with_suffix("").as_posix(), Path(n).stem}:
            by_key.setdefault(k, []).append(i)
    assigned: dict[int, str] = {}
    for split, f in files.items():
        for ln, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            n = _norm_name(s)
            hits = None
            for k in (n, Path(n).with_suffix("").as_posix(), n.rsplit("/", 1)[-1], Path(n).stem):
                if k in by_key:
                    hits = by_key[k]
                    break
            if hits is None:
                raise SceneFormatError(f"{f}:{ln}: image {s!r} is not a camera of this scene "
                                       "(not in images.bin / images_val.bin / transforms.json)")
            if len(hits) > 1:
                raise SceneFormatError(f"{f}:{ln}: image {s!r} is ambiguous ({len(hits)} cameras match)")
            i = hits[0]
            if assigned.get(i, split) != split:
                raise SceneFormatError(f"{f}:{ln}: image {s!r} is listed in both train.txt and val.txt")
            assigned[i] = split
    for i, split in assigned.items():
        cams[i].split = split
    unlisted = len(cams) - len(assigned)
    if unlisted:
        log.info("%s: %d camera(s) not named in nvs_split keep their default split", root, unlisted)


# --------------------------------------------------------------------------- points


def _check_finite(path: Path, xyz: np.ndarray) -> None:
    bad = ~np.isfinite(xyz)
    if bad.any():
        col = "xyz"[int(np.argwhere(bad)[0, 1])]
        raise SceneFormatError(f"{path}: {int(bad.any(-1).sum())} point(s) with non-finite property '{col}'")


def _load_v1_points(root: Path) -> tuple[np.ndarray, np.ndarray]:
    p = root / "raw_pcd.ply"
    if p.is_file():
        try:
            pc = read_ply_points(p)
        except PointCloudFormatError as e:
            raise SceneFormatError(str(e)) from None
        _check_finite(p, pc.xyz)
        rgb = pc.rgb if pc.rgb is not None else np.full((len(pc), 3), 128, np.uint8)
        if pc.rgb is None:
            log.warning("%s: no red/green/blue properties: points coloured grey", p)
        return pc.xyz, rgb
    sdir = _sparse_dir(root)
    if sdir is not None:
        ext = C.detect_model_ext(sdir)
        pf = sdir / f"points3D{ext}"
        if pf.is_file():
            log.warning("%s: no raw_pcd.ply: using the SfM points in %s (not metric LiDAR)", root, pf)
            try:
                pts = C.read_points3D_bin(pf) if ext == ".bin" else C.read_points3D_txt(pf)
            except C.ColmapFormatError as e:
                raise SceneFormatError(str(e)) from None
            _check_finite(pf, pts.xyz)
            return pts.xyz.astype(np.float32), pts.rgb
    log.warning("%s: no raw_pcd.ply and no points3D: the scene has no points", root)
    return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)


#: default limit (m) between consecutive `lidar/poses.txt` poses: scans are registered by their overlap, and a
#: vehicle LiDAR sees ~100 m (Velodyne HDL-64: 120 m), so consecutive scans further apart share nothing; a
#: translation in millimetres puts a scan kilometres away. `scene_meta.json` `lidar_max_pose_jump` overrides it
MAX_POSE_JUMP = 100.0


def _read_kitti_poses(path: Path, files: list[Path], max_jump: float) -> np.ndarray:
    """KITTI poses file: one row-major 3x4 world_from_lidar per line (`#` comments and blank lines
    skipped) -> `[n,4,4]`, one per scan in `files` (exactly). Errors quote the file's 1-based line number."""
    n = len(files)
    rows, lines = [], []
    for ln, text in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        t = text.split("#", 1)[0].split()
        if not t:
            continue
        try:
            vals = [float(x) for x in t]
        except ValueError:
            raise SceneFormatError(f"{path}:{ln}: pose line is not 12 numbers: {text.strip()[:80]!r}") from None
        if len(vals) != 12:
            raise SceneFormatError(f"{path}:{ln}: a pose line needs 12 numbers (row-major 3x4), got {len(vals)}")
        rows.append(vals)
        lines.append(ln)
    if len(rows) != n:  # one scan more or fewer shifts every later pose onto the wrong scan
        raise SceneFormatError(f"{path}: {len(rows)} poses for {n} lidar scans ({files[0].name} .. {files[-1].name}); "
                               "poses.txt needs exactly one line per scan, in the scans' name order")
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :] = np.asarray(rows).reshape(n, 3, 4)
    for i in range(n):  # tens of frames: per-pose checks so the message names the line
        try:
            validate_rigid(T[i], what=f"{path}:{lines[i]}: pose")
        except ValueError as e:
            raise SceneFormatError(str(e).replace(" at index [0]", "")) from None
    jumps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)  # [n-1] metres between consecutive scans
    if n > 1 and jumps.max() > max_jump:
        i = int(jumps.argmax())
        raise SceneFormatError(
            f"{path}:{lines[i + 1]}: pose of {files[i + 1].name} is {jumps[i]:.1f} m from the previous one "
            f"(line {lines[i]}, {files[i].name}); consecutive scans further apart than {max_jump:g} m cannot "
            "overlap (a translation in millimetres, or a missing scan?). If the capture really jumps, set "
            "\"lidar_max_pose_jump\": <metres> in scene_meta.json")
    return T


def _scan_poses(root: Path, files: list[Path], meta) -> np.ndarray | None:
    """world_from_sensor `[K,4,4]` for the `lidar/` files: `poses.txt`; identity for one KITTI `.bin` scan
    (its points are in the sensor frame); None for a registered cloud. Several files without poses are
    an error unless `scene_meta.json` says `"lidar_registered": true`: stacking unmoved scans is wrong."""
    ldir = root / "lidar"
    if (ldir / "poses.txt").is_file():
        jump = meta.raw.get("lidar_max_pose_jump", MAX_POSE_JUMP) if meta else MAX_POSE_JUMP
        if not np.isfinite(jump) or jump <= 0:
            raise SceneFormatError(f"{meta.path}: field 'lidar_max_pose_jump' must be a number > 0 (metres), "
                                   f"got {jump!r}")
        return _read_kitti_poses(ldir / "poses.txt", files, float(jump))
    registered = bool(meta.raw.get("lidar_registered", False)) if meta else False
    if len(files) > 1 and not registered:
        raise SceneFormatError(
            f"{ldir}: {len(files)} scans but no poses.txt: scans in their sensor frames would be stacked "
            "unmoved. Add lidar/poses.txt (one KITTI 3x4 world_from_lidar per scan, in name order) or, if "
            "the files are already in one world frame, set \"lidar_registered\": true in scene_meta.json")
    if len(files) == 1 and files[0].suffix.lower() == ".bin" and not registered:
        return np.eye(4)[None]
    return None


#: default self-return radius (m) for vehicle sweeps: KITTI's roof Velodyne sees its own car (roof, hood,
#: mirrors) up to 2.6 m away; a passenger car reaches ~2.5 m from its roof centre or rear axle
VEHICLE_SWEEP_MIN_RANGE = 2.7


def _lidar_min_range(meta, poses, files: list[Path]) -> tuple[float, str]:
    """`(radius m, where it came from)`: returns closer than this to the sensor (horizontal, in each scan's own
    frame) are the capture platform (a car's roof, hood and mirrors seen by its roof LiDAR: KITTI ~2.6 m) and
    are dropped; they would be obstacles inside the blind spot under the path. `scene_meta.json`
    `lidar_min_range` wins; else vehicle sweeps (KITTI `.bin` records in their sensor frames, i.e. with
    `lidar/poses.txt` or a single scan) get `VEHICLE_SWEEP_MIN_RANGE`, everything else (registered clouds,
    hand-held `.ply`/`.las` scans whose platform is a person) 0."""
    if meta is None or "lidar_min_range" not in meta.raw:
        if poses is not None and all(f.suffix.lower() == ".bin" for f in files):
            return VEHICLE_SWEEP_MIN_RANGE, "default for vehicle sweeps (.bin scans in their sensor frames)"
        return 0.0, "default (not vehicle sweeps)"
    r = meta.raw["lidar_min_range"]
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not np.isfinite(r) or r < 0:
        raise SceneFormatError(f"{meta.path}: field lidar_min_range must be a number >= 0 (metres), got {r!r}")
    if r > 0 and poses is None:
        raise SceneFormatError(f"{meta.path}: field lidar_min_range needs scans in their sensor frames "
                               "(lidar/poses.txt or one .bin scan); these files are a registered cloud")
    return float(r), f"{meta.path.name} lidar_min_range"


def _load_v2_points(root: Path, meta) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, dict | None]:
    """`lidar/` frames (sorted by name), moved by `lidar/poses.txt` when present; else the mesh vertices.
    Returns (points, colours, world_from_sensor poses or None, the self-return filter applied or None)."""
    files = _lidar_files(root)
    if files:
        poses = _scan_poses(root, files, meta)
        min_range, source = _lidar_min_range(meta, poses, files)
        xyzs, rgbs, dropped = [], [], 0
        for i, f in enumerate(files):  # one iteration per LiDAR frame (tens), points are batched
            try:
                pc = read_points_any(f)
            except PointCloudFormatError as e:
                raise SceneFormatError(str(e)) from None
            if len(pc) == 0:
                raise SceneFormatError(f"{f}: empty scan (0 points)")
            _check_finite(f, pc.xyz)
            if not pc.xyz.any():  # a zero-filled file (a failed copy, a placeholder) reads as points at the sensor
                raise SceneFormatError(f"{f}: all {len(pc)} points are (0, 0, 0): a zero-filled scan, not a capture")
            xyz, rgb = pc.xyz, pc.rgb
            if min_range > 0:  # sensor frame: returns from the capture platform itself
                far = np.linalg.norm(xyz[:, :2], axis=1) >= min_range
                dropped += int((~far).sum())
                xyz, rgb = xyz[far], rgb[far] if rgb is not None else None
            if poses is not None and not np.array_equal(poses[i], np.eye(4)):
                xyz = (xyz.astype(np.float64) @ poses[i, :3, :3].T + poses[i, :3, 3]).astype(np.float32)
            xyzs.append(xyz)
            rgbs.append(rgb if rgb is not None else np.full((len(xyz), 3), 128, np.uint8))
        if min_range > 0:
            log.info("%s: dropped %d LiDAR returns within %.2f m of the sensor (the capture platform; %s)",
                     root, dropped, min_range, source)
        filt = {"min_range_m": min_range, "source": source, "points_dropped": dropped}
        return np.concatenate(xyzs), np.concatenate(rgbs), poses, filt
    mesh = root / "scene.ply"
    if mesh.is_file():
        log.warning("%s: no lidar/ frames: using scene.ply vertices as the point cloud", root)
        try:
            pc = read_ply_points(mesh)
        except PointCloudFormatError as e:
            raise SceneFormatError(str(e)) from None
        _check_finite(mesh, pc.xyz)
        return pc.xyz, pc.rgb if pc.rgb is not None else np.full((len(pc), 3), 128, np.uint8), None, None
    raise SceneFormatError(f"{root}: v2 scene has neither lidar/*{{{','.join(LIDAR_SUFFIXES)}}} nor scene.ply")
