"""Scene preparation: scene folder -> `collision_mesh.ply` -> `navmesh.npz`, cached and idempotent.

Each artefact gets a JSON sidecar (`collision_mesh.json`, `navmesh.json`) holding one hash of the
settings that produced it and of the *contents* of the inputs it was built from (each input's sha256
is listed too), and summary figures. A step is skipped when its output exists, is intact, and the
stored hash matches the current settings and input contents, so re-running `prepare` is cheap and
changing one setting or one scan rebuilds only what depends on it. Modification times are never
trusted: `cp -p` / `rsync -a` replace a scan and keep its old time. All files are written atomically
(`wanderland_nav.atomic`).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from pathlib import Path

import numpy as np
import trimesh

from planners import NavMesh, NavMeshSettings
from wanderland_nav.atomic import atomic_path, atomic_write_json
from wanderland_nav.cache import file_sha256, json_digest, read_record
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import parse_up_axis
from wanderland_nav.scene import make_demo_scene
from wanderland_nav.scene.checks import EmptyNavMeshError, check_up_axis, empty_navmesh_reasons
from wanderland_nav.scene.collision import (CollisionSettings, crop_mesh_to_trajectory, extract_collision_mesh,
                                            load_collision_mesh)
from wanderland_nav.scene.loader import load_scene, visible_files
from wanderland_nav.scene.types import Scene

log = logging.getLogger(__name__)

COLLISION_MESH = "collision_mesh.ply"
NAVMESH = "navmesh.npz"
_FORMAT = 3  # bump when the meaning of an artefact changes, so stale caches rebuild (2: ground sheet, lidar filter;
# 3: keyed by input contents)


def _sidecar(path: Path) -> Path:
    return path.with_suffix(".json")


def _read_sidecar(path: Path) -> dict | None:
    return read_record(_sidecar(path))


def scene_inputs(root: Path) -> list[Path]:
    """Files whose change invalidates the collision mesh (points, poses, up axis); hidden files are no input."""
    root = Path(root)
    cands = [root / "raw_pcd.ply", root / "scene.ply", root / "scene_meta.json", root / "transforms.json"]
    for d in (root / "sparse" / "0", root / "sparse", root / "lidar"):
        cands += visible_files(d)
    return sorted(p for p in cands if p.is_file())


def _file_digest(path: Path) -> str:
    return file_sha256(path)[:16]


def input_digests(root: Path, inputs: list[Path]) -> dict[str, str]:
    """`{path relative to the scene folder: sha256[:16]}` of each input (what the cache key is made of)."""
    return {p.relative_to(root).as_posix(): _file_digest(p) for p in inputs}


def _up_to_date(output: Path, settings_hash: str, load) -> bool:
    """Output exists, its sidecar's hash (settings and input contents) matches, and it is intact: its bytes
    hash to the sidecar's `sha256` (a few ms), or, for sidecars written before that field, `load(output)`
    reads it. A truncated or corrupt artefact (killed copy, full disk) is rebuilt, never called up to date."""
    if not output.is_file():
        return False
    side = _read_sidecar(output)
    if side is None or side.get("settings_hash") != settings_hash:
        return False
    if "sha256" in side:
        if side["sha256"] == _file_digest(output):
            return True
        log.warning("%s: content does not match its sidecar (truncated or modified); rebuilding it", output)
        return False
    try:
        load(output)
    except ValueError as e:  # WanderlandInputError / NavMeshFileError: both name the file
        log.warning("%s: cached artefact does not load (%s); rebuilding it", output, e)
        return False
    return True


def capture_positions(scene: Scene) -> np.ndarray:
    """Scene-frame positions `[M,3]` of the capture trajectory: camera centres, else the v2
    `lidar/poses.txt` sensor positions, else none (the cloud is then used uncropped)."""
    return scene.capture_positions()


def build_collision_mesh(scene: Scene, settings: CollisionSettings, *, force: bool = False) -> tuple[Path, dict]:
    """Write `collision_mesh.ply` (+ sidecar) for `scene` unless up to date. Returns (path, sidecar)."""
    out = scene.products / COLLISION_MESH
    inputs = scene_inputs(scene.root)
    digests = input_digests(scene.root, inputs)
    h = json_digest({"format": _FORMAT, "settings": settings.result_dict(), "up_axis": scene.up_axis,
                     "inputs": digests})
    if not force and _up_to_date(out, h, load_collision_mesh):
        log.info("%s is up to date", out)
        side = _read_sidecar(out)
        side["skipped"] = True
        return out, side
    if not np.isfinite(scene.points).all(-1).any():  # empty, or nothing finite
        raise WanderlandInputError(f"scene {scene.name!r} has no finite points among {len(scene.points)}: the "
                                   f"collision mesh needs a point cloud "
                                   f"(raw_pcd.ply, points3D or lidar/ scans; inputs found: "
                                   f"{[p.name for p in inputs]})", path=scene.root)
    t0 = time.perf_counter()
    if settings.use_scene_mesh and scene.mesh_path is not None:  # v2: the shipped TSDF mesh, cropped
        mesh = crop_mesh_to_trajectory(trimesh.load(scene.mesh_path, file_type="ply", process=False, force="mesh"),
                                       capture_positions(scene), scene.up_axis, settings)
    else:
        mesh = extract_collision_mesh(scene.points, capture_positions(scene), scene.up_axis, settings=settings)
    meta = mesh.metadata.pop("collision")
    with atomic_path(out) as tmp:
        mesh.export(tmp, file_type="ply")
    side = {"settings_hash": h, "sha256": _file_digest(out), "settings": settings.as_dict(), "up_axis": scene.up_axis,
            "inputs": digests, "faces": int(len(mesh.faces)), "vertices": int(len(mesh.vertices)),
            "points_in": meta["points_in"], "points_kept": meta["points_kept"], "grid_shape": meta["grid_shape"],
            "timings": {**meta["timings"], "write_s": time.perf_counter() - t0 - meta["timings"]["total_s"]},
            "ground_fill": meta.get("ground_fill"), "lidar_filter": scene.meta.get("lidar_filter"), "skipped": False}
    atomic_write_json(_sidecar(out), side)
    return out, side


def build_navmesh(scene: Scene, navmesh_settings, *, force: bool = False) -> tuple[Path, dict]:
    """Bake `navmesh.npz` from `collision_mesh.ply` with `planners.NavMesh` unless up to date."""
    settings = navmesh_settings if navmesh_settings is not None else NavMeshSettings(up_axis=scene.up_axis)
    if settings.up_axis != scene.up_axis:
        log.info("navmesh up_axis %s replaced by the scene's %s (%s)", settings.up_axis, scene.up_axis,
                 scene.up_axis_source)
        settings = dataclasses.replace(settings, up_axis=scene.up_axis)
    cm = scene.products / COLLISION_MESH
    out = scene.products / NAVMESH
    cm_side = _read_sidecar(cm) or {}
    # the collision mesh's own bytes, not its sidecar: a mesh replaced by hand keeps the sidecar it found
    h = json_digest({"format": _FORMAT, "bake": settings.bake_hash(),
                     "collision": _file_digest(cm) if cm.is_file() else None})
    if not force and _up_to_date(out, h, NavMesh.load):
        log.info("%s is up to date", out)
        side = _read_sidecar(out)
        side["skipped"] = True
        return out, side
    t0 = time.perf_counter()
    mesh = load_collision_mesh(cm)
    nm = NavMesh.bake(mesh, settings)
    t_bake = time.perf_counter() - t0
    islands = _island_summary(nm)
    if sum(i["area"] for i in islands) <= 0:  # never replace a cached navmesh with an empty one; say why
        raise EmptyNavMeshError(empty_navmesh_reasons(scene, settings, cm_side))
    nm.save(out)  # NavMesh.save writes atomically
    side = {"settings_hash": h, "sha256": _file_digest(out), "settings": settings.to_dict(),
            "collision_settings_hash": cm_side.get("settings_hash"),
            "islands": islands, "num_islands": len(islands), "area_m2": float(sum(i["area"] for i in islands)),
            "timings": {"bake_s": t_bake, "total_s": time.perf_counter() - t0}, "skipped": False}
    atomic_write_json(_sidecar(out), side)
    return out, side


def _island_summary(nm) -> list[dict]:
    out = []
    for isl in getattr(nm, "islands", []) or []:
        get = (lambda k: isl.get(k)) if isinstance(isl, dict) else (lambda k: getattr(isl, k, None))
        out.append({"id": int(get("id")) if get("id") is not None else len(out),
                    "area": float(get("area") or 0.0), "radius": float(get("radius") or 0.0)})
    return out


def check_navmesh_frame(scene: Scene) -> None:
    """Refuse a `navmesh.npz` beside the scene that was baked for another up axis than the scene's (a copied
    navmesh, an up axis changed in scene_meta.json after prepare): its floors would be walls. Checked where a
    scene is prepared or its artefacts are taken as they are, so the error names the file and both axes here,
    not deep inside the episode sampler. Unreadable files are left to `NavMesh.load` to report."""
    path = scene.navmesh_path
    if path is None or not Path(path).is_file():
        return
    try:
        with np.load(path, allow_pickle=False) as z:
            baked = json.loads(str(z["meta"]))["settings"]["up_axis"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    if parse_up_axis(baked) != parse_up_axis(scene.up_axis):
        raise WanderlandInputError(
            f"navmesh baked for up axis {baked}, but the scene's up axis is {scene.up_axis} (from "
            f"{scene.up_axis_source}); re-run prepare for this scene (python -m wanderland_nav.prepare "
            f"scene={scene.root} navigation.prepare=true), or set scene.up_axis={baked} if the navmesh is right",
            path=path, field="settings.up_axis")


def prepare_scene(path, *, force: bool = False, collision: CollisionSettings = CollisionSettings(),
                  navmesh=None, up_axis: str | None = None, bake_navmesh: bool = True) -> Scene:
    """Collision mesh then navmesh beside the scene (skipping what is up to date); returns the
    Scene (loaded once, output paths filled in) with `scene.meta["prepare"]` = the two sidecars (figures, timings, skipped flags)."""
    scene = load_scene(path, up_axis=up_axis)
    check_up_axis(scene)
    cm_path, cm_side = build_collision_mesh(scene, collision, force=force)
    scene.collision_mesh_path = cm_path  # the loaded scene is otherwise unchanged: no second read
    report = {"collision_mesh": cm_side}
    if bake_navmesh:
        nm_path, nm_side = build_navmesh(scene, navmesh, force=force)
        scene.navmesh_path = nm_path
        report["navmesh"] = nm_side
    check_navmesh_frame(scene)
    scene.meta = {**scene.meta, "prepare": report}
    return scene


def ensure_demo_scene(path, seed: int = 0, preset: str = "default", **prepare_kwargs) -> Scene:
    """Make the procedural demo scene at `path` if missing (idempotent), then prepare it."""
    make_demo_scene(Path(path), seed=seed, preset=preset)
    return prepare_scene(path, **prepare_kwargs)
