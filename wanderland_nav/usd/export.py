"""`export_scene_usd(scene, out)`: collision mesh, navmesh, Gaussians, capture cameras and episode
starts of one prepared scene in one `.usda` / `.usdc` / `.usdz` file (layout in `usd.stage`)."""

from __future__ import annotations

import logging
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from planners import NavMesh
from wanderland_nav.atomic import atomic_path
from wanderland_nav.episodes.schema import load_episodes
from wanderland_nav.usd import stage as S

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UsdExportSettings:
    """What goes into the stage. Missing inputs (no navmesh, no 3dgs.ply, no episodes) are skipped
    with a log line; `require_*` turns a missing one into an error."""

    gaussians: bool = True
    max_gaussians: int | None = None  # None: all; else an evenly spaced subset (logged)
    cameras: bool = True
    episodes: bool = True
    require_collision_mesh: bool = True


def _require_pxr():
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise ImportError("USD export needs usd-core: pip install 'wanderland_nav[usd]'") from None


def build_stage(scene, settings: UsdExportSettings = UsdExportSettings()):
    """An in-memory `Usd.Stage` of `scene` (a prepared `Scene`); returns (stage, summary dict)."""
    _require_pxr()
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    root = UsdGeom.Xform.Define(stage, "/World/Scene")
    T = np.eye(4)
    T[:3, :3] = scene.nav_from_scene  # scene frame -> Z-up stage
    root.AddTransformOp().Set(S._mat(T))
    root.GetPrim().SetCustomDataByKey("wanderland:up_axis", scene.up_axis)
    summary = {"up_axis": scene.up_axis}

    if scene.collision_mesh_path is None:
        if settings.require_collision_mesh:
            raise FileNotFoundError(f"{scene.root}: no collision_mesh.ply: run `python -m wanderland_nav.prepare "
                                    f"scene={scene.root}` first")
    else:
        m = trimesh.load(scene.collision_mesh_path, file_type="ply", process=False, force="mesh")
        S.add_collision_mesh(stage, "/World/Scene/Collision", np.asarray(m.vertices), np.asarray(m.faces))
        summary["collision_faces"] = int(len(m.faces))
    if scene.navmesh_path is not None:
        nm = NavMesh.load(scene.navmesh_path)
        S.add_navmesh(stage, "/World/Scene/NavMesh", nm)
        summary["navmesh_faces"] = int(len(nm.tris))
    if settings.gaussians and scene.gaussians_path is not None:
        summary["gaussians"] = S.add_gaussians(stage, "/World/Scene/Gaussians", scene.gaussians_path,
                                               settings.max_gaussians)
    if settings.cameras and scene.cameras:
        S.add_cameras(stage, "/World/Scene/Cameras", scene.cameras)
        summary["cameras"] = len(scene.cameras)
    if settings.episodes and scene.episodes_path is not None:
        eps = load_episodes(scene.episodes_path)
        S.add_episode_starts(stage, "/World/Scene/EpisodeStarts", eps, scene.nav_from_scene)
        summary["episodes"] = len(eps)
    skipped = [k for k in ("navmesh_faces", "gaussians", "cameras", "episodes") if k not in summary]
    if skipped:
        log.info("%s: USD export without %s (not in the scene or turned off)", scene.root, ", ".join(skipped))
    return stage, summary


def export_scene_usd(scene, out, settings: UsdExportSettings = UsdExportSettings()) -> dict:
    """Write the stage to `out` (`.usda`, `.usdc`, `.usd` or `.usdz`), atomically; returns the summary."""
    out = Path(out)
    if out.suffix not in (".usda", ".usdc", ".usd", ".usdz"):
        raise ValueError(f"{out}: USD output must end in .usda, .usdc, .usd or .usdz")
    stage, summary = build_stage(scene, settings)
    with atomic_path(out) as tmp:
        if out.suffix == ".usdz":  # a package: the layer is written first, then zipped
            from pxr import UsdUtils

            with tempfile.TemporaryDirectory() as d:
                layer = Path(d) / f"{out.stem}.usdc"
                stage.GetRootLayer().Export(str(layer))
                if not UsdUtils.CreateNewUsdzPackage(str(layer), str(tmp)):
                    raise RuntimeError(f"{out}: usdz packaging failed")
        else:
            stage.GetRootLayer().Export(str(tmp))
    summary["out"] = str(out)
    return summary
