"""`build_degraded_scene(src, out, spec)`: a degraded copy of a grounded scene folder.

The output is an ordinary v1 scene folder (COLMAP model, `raw_pcd.ply`, `3dgs.ply`, images,
`scene_meta.json`), so `prepare`, `expert`, `train` and `evaluate` consume it unchanged. A LiDAR-only v2
scene (`lidar/*.bin` + `lidar/poses.txt`, no camera model) gets a LiDAR-only copy instead
(`lidar_only.py`: each scan moves with its own degraded pose). What changes:

* every pose and every reconstructed point/Gaussian goes through the pose-error field
  (`poses.PoseCorrection`: drift about the camera that saw it, then the global scale);
* with `geometry="splats"`, `raw_pcd.ply` holds points fused from depth rendered out of the splats
  instead of the LiDAR cloud;
* holes and dropped fragments are cut from that cloud at the spec's stated rates.

Written beside it: `degradation.npz` (the pose-error field, to map grounded positions into this
scene, e.g. to test which grounded expert episodes stay feasible) and a `degradation` block in
`scene_meta.json` (spec, source, figures). Not copied: the prepared artefacts and episodes (they are
rebuilt for the degraded world), `depth/` (metric depth no longer matches a moved world) and
`gt_mesh.ply` (ground truth stays with the grounded scene). Images and masks are hard-linked.

The build happens in a temporary sibling folder renamed into place; a marker with the hash of the
spec and of the source's inputs (their contents) makes a rerun return at once, and a folder the project did not
write is never replaced.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import file_sha256, json_digest, read_record
from wanderland_nav.geometry import quat_to_rotmat, rotmat_to_quat
from wanderland_nav.render import Gaussians
from wanderland_nav.scene import colmap as C, load_scene
from wanderland_nav.scene.lidar_splat import META_KEY as LIDAR_SPLAT, LidarSplatSettings
from wanderland_nav.scene.pointcloud import write_ply_points

from .damage import fragment_mask, hole_mask, horizontal_xy
from .lidar_only import write_lidar_only
from .poses import PoseCorrection, pose_correction
from .spec import DegradeSpec
from .splat_points import splat_depth_points

log = logging.getLogger(__name__)

MARKER = ".degraded_scene.json"
CORRECTION = "degradation.npz"
_REWRITTEN = {"raw_pcd.ply", "3dgs.ply", "transforms.json", "scene_meta.json", "images_val.bin", "images_val.txt"}
_NOT_COPIED_DIRS = {"sparse", "depth", "goal_images", "lidar"}
_NOT_COPIED_PREFIX = ("collision_mesh", "navmesh", "episodes", "gt_mesh", ".")


def _source_key(src: Path, spec: DegradeSpec) -> str:
    """Hash of the spec and of every input file's name and bytes (sha256), never its modification time: a
    scan or splat replaced with `cp -p` or `rsync -a` (new bytes, old time) makes a new build. Images and
    masks are left out: they are hard-linked into the copy, not read."""
    files = [p for p in sorted(src.rglob("*")) if p.is_file() and p.relative_to(src).parts[0] not in
             ("images", "images_mask", "depth", "goal_images") and not p.name.startswith(_NOT_COPIED_PREFIX)]
    return json_digest([spec.as_dict(), [(p.relative_to(src).as_posix(), file_sha256(p)) for p in files]])


def _sparse_dir(root: Path) -> Path | None:
    for d in (root / "sparse" / "0", root / "sparse"):
        if (d / "images.bin").is_file() or (d / "images.txt").is_file():
            return d
    return None


def _link_tree(src: Path, dst: Path) -> None:
    """Hard-link (else copy) every file of `src` that a degraded scene keeps."""
    for p in sorted(src.iterdir()):
        if p.name in _REWRITTEN or p.name.startswith(_NOT_COPIED_PREFIX) or p.name in _NOT_COPIED_DIRS:
            continue
        if p.is_dir():
            shutil.copytree(p, dst / p.name, copy_function=_link_or_copy)
        elif p.is_file() and p.suffix.lower() != ".png":  # loose PNGs are plots of the grounded scene
            _link_or_copy(p, dst / p.name)


def _link_or_copy(a, b) -> None:
    try:
        os.link(a, b)
    except OSError:
        shutil.copy2(a, b)


def _degrade_colmap(sdir: Path, src: Path, dst: Path, corr: PoseCorrection) -> None:
    ext = C.detect_model_ext(sdir)
    model = C.read_model(sdir, ext)
    _move_images(model.images, corr)
    if len(model.points3D):
        model.points3D.xyz = corr.apply_points(model.points3D.xyz)
    C.write_model(dst / sdir.relative_to(src), model, ext)
    for d in (sdir, src):  # the val poses live beside the model or in the root, as the loader looks for them
        for vext in (".bin", ".txt"):
            p = d / f"images_val{vext}"
            if p.is_file():
                imgs = C.read_images_bin(p) if vext == ".bin" else C.read_images_txt(p)
                _move_images(imgs, corr)
                out = dst / p.relative_to(src)
                (C.write_images_bin if vext == ".bin" else C.write_images_txt)(out, imgs)


def _move_images(images: dict, corr: PoseCorrection) -> None:
    for im in images.values():
        T = corr.apply_poses(im.world_from_cam()[None])[0]
        R = T[:3, :3].T  # cam_from_world
        im.qvec = C.rotmat_to_qvec(R)
        im.tvec = -R @ T[:3, 3]


def _degrade_transforms(src: Path, dst: Path, corr: PoseCorrection) -> None:
    p = src / "transforms.json"
    if not p.is_file():
        return
    obj = json.loads(p.read_text())
    frames = [f for f in obj.get("frames", []) if isinstance(f, dict) and "transform_matrix" in f]
    if frames:
        T = np.asarray([f["transform_matrix"] for f in frames], dtype=np.float64)  # camera-to-world
        for f, t in zip(frames, corr.apply_poses(T)):
            f["transform_matrix"] = t.tolist()
    atomic_write_json(dst / "transforms.json", obj)


def _degrade_gaussians(path: Path, out: Path, corr: PoseCorrection) -> None:
    g = Gaussians.load(path, dtype=torch.float64)
    mu = g.means.numpy()
    idx = corr.nearest(mu)
    R = quat_to_rotmat(g.quats).numpy()
    g.means = torch.from_numpy(corr.apply_points(mu, idx))
    g.quats = rotmat_to_quat(torch.from_numpy(corr.apply_rotations(mu, R, idx)))
    g.log_scales = g.log_scales + float(np.log(corr.scale))
    g.save(out)


def _meta(src: Path, scene, spec: DegradeSpec, figures: dict) -> dict:
    p = src / "scene_meta.json"
    meta = json.loads(p.read_text()) if p.is_file() else {}
    s = spec.scale
    regions = [{**r, "polygon_xy": (np.asarray(r["polygon_xy"], dtype=np.float64) * s).tolist(),
                **{k: float(r[k]) * s for k in ("z_min", "z_max") if k in r}}
               for r in meta.get("indoor_regions", [])]
    gen = meta.pop("generator", None)
    if "lidar_min_range" in meta:  # sensor-frame metres: the scans are scaled with the world
        meta["lidar_min_range"] = float(meta["lidar_min_range"]) * s
    if LIDAR_SPLAT in meta:  # rebuilt from the degraded scans (lidar_only.py) with its metric settings scaled
        settings = dataclasses.asdict(LidarSplatSettings(**meta[LIDAR_SPLAT]["settings"]).scaled(s))
        meta[LIDAR_SPLAT] = {**meta[LIDAR_SPLAT], "settings": settings, "figures": {
            k[len("splat_"):]: v for k, v in figures.items() if k.startswith("splat_")}}
    return {**meta, "name": f"{scene.name}__{spec.name}", "up_axis": scene.up_axis, "indoor_regions": regions,
            "degradation": {"spec": spec.as_dict(), "source": str(src), "source_name": scene.name,
                            "source_generator": gen, "figures": figures}}


def build_degraded_scene(src, out, spec: DegradeSpec, *, up_axis: str | None = None, device: str = "cpu") -> Path:
    """Write the degraded copy of scene folder `src` at `out` (see the module docstring); returns `out`."""
    src, out = Path(src).resolve(), Path(out)
    key = _source_key(src, spec)
    marker = out / MARKER
    if marker.is_file():
        if (read_record(marker) or {}).get("key") == key:  # an unreadable marker: rebuilt (and said so)
            log.info("%s is up to date (%s of %s)", out, spec.name, src)
            return out
    elif out.exists():
        raise FileExistsError(f"{out}: exists and was not written by wanderland_nav.degrade (no {MARKER}); "
                              "choose another output folder")
    scene = load_scene(src, up_axis=up_axis)
    sdir = _sparse_dir(src)
    lidar_only = sdir is None and not scene.cameras and scene.lidar_poses is not None
    if not lidar_only and (sdir is None or not scene.cameras):
        raise ValueError(f"{src}: degraded builds need a capture trajectory: a COLMAP model (sparse/0) or "
                         f"LiDAR scans with lidar/poses.txt; this scene has {len(scene.cameras)} cameras and neither")
    pose_rng, damage_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(spec.seed).spawn(2))
    corr = pose_correction(scene.capture_positions(), scene.up_axis, spec, pose_rng)
    if lidar_only:
        return _write_scene(out, marker, key, spec, src, scene, corr,
                            lambda tmp: write_lidar_only(src, tmp, scene, spec, corr, damage_rng))

    if spec.geometry == "splats":
        if scene.gaussians_path is None:
            raise ValueError(f"{src}: geometry='splats' needs 3dgs.ply, which this scene lacks")

        xyz, rgb = splat_depth_points(Gaussians.load(scene.gaussians_path), scene.cameras,
                                      size=spec.splat_render_size, min_alpha=spec.splat_min_alpha, device=device)
    else:
        xyz, rgb = scene.points, scene.colors
    xy = horizontal_xy(xyz, scene.up_axis)
    keep_h, n_holes = hole_mask(xy, damage_rng, spec.hole_rate_per_100m2, spec.hole_radius)
    keep_f, n_tiles = fragment_mask(xy, damage_rng, spec.fragment_drop_rate, spec.fragment_tile)
    keep = keep_h & keep_f
    figures = {"points_in": int(len(xyz)), "points_kept": int(keep.sum()), "holes": n_holes,
               "fragments_dropped": n_tiles, "lidar_points": int(len(scene.points))}


    def write(tmp: Path) -> dict:
        _link_tree(src, tmp)
        write_ply_points(tmp / "raw_pcd.ply", corr.apply_points(xyz[keep]).astype(np.float32), rgb[keep])
        _degrade_colmap(sdir, src, tmp, corr)
        _degrade_transforms(src, tmp, corr)
        if scene.gaussians_path is not None:
            _degrade_gaussians(scene.gaussians_path, tmp / "3dgs.ply", corr)
        return figures

    return _write_scene(out, marker, key, spec, src, scene, corr, write)


def _write_scene(out: Path, marker: Path, key: str, spec: DegradeSpec, src: Path, scene, corr: PoseCorrection,
                 write) -> Path:
    """`write(tmp) -> figures` fills a temporary sibling folder; then the correction field, the metadata
    and the marker are added and the folder is renamed into place."""
    tmp = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        figures = write(tmp)
        corr.save(tmp / CORRECTION)
        atomic_write_json(tmp / "scene_meta.json", _meta(src, scene, spec, figures))
        atomic_write_json(tmp / MARKER, {"key": key, "spec": spec.as_dict(), "source": str(src)})
        if out.exists():
            shutil.rmtree(out)  # ours (it has the marker) but stale
        os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    log.info("wrote %s (%s of %s): %s", out, spec.name, src, figures)
    return out
