"""USD export round trip: write the prepared demo scene (v1 frame, -y up) with usd-core, read it back."""

from __future__ import annotations

import numpy as np
import torch
import pytest
import trimesh

pxr = pytest.importorskip("pxr")


@pytest.fixture(scope="module")
def exported(prepared_demo_scene, demo_episodes, tmp_path_factory):
    from wanderland_nav.scene import load_scene
    from wanderland_nav.usd import UsdExportSettings, export_scene_usd

    scene = load_scene(prepared_demo_scene)
    out = tmp_path_factory.mktemp("usd") / "scene.usda"
    summary = export_scene_usd(scene, out, UsdExportSettings(max_gaussians=2000))
    return scene, out, summary


def _points(prim):
    from pxr import UsdGeom

    return np.asarray(UsdGeom.PointBased(prim).GetPointsAttr().Get(), dtype=np.float64)


def test_stage_frame_and_collision_mesh(exported):
    from pxr import Usd, UsdGeom, UsdPhysics

    scene, out, summary = exported
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"
    root = stage.GetPrimAtPath("/World/Scene")
    assert root.GetCustomDataByKey("wanderland:up_axis") == scene.up_axis == "-y"
    M = np.asarray(UsdGeom.Xformable(root).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T  # column form
    np.testing.assert_allclose(M[:3, :3], scene.nav_from_scene, atol=1e-12)

    col = stage.GetPrimAtPath("/World/Scene/Collision")
    ref = trimesh.load(scene.collision_mesh_path, file_type="ply", process=False, force="mesh")
    pts = _points(col)
    assert len(pts) == len(ref.vertices) and summary["collision_faces"] == len(ref.faces)
    assert len(UsdGeom.Mesh(col).GetFaceVertexIndicesAttr().Get()) == 3 * len(ref.faces)
    np.testing.assert_allclose([pts.min(0), pts.max(0)], ref.bounds, atol=1e-4)  # scene frame, float32
    assert col.HasAPI(UsdPhysics.CollisionAPI) and UsdGeom.Imageable(col).ComputeVisibility() == "invisible"
    # in the stage (Z-up) frame the floor of the demo is horizontal: world z spread of floor-level points is small
    bbox = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default", "render", "proxy", "guide"]).ComputeWorldBound(col)
    rng = bbox.ComputeAlignedRange()
    np.testing.assert_allclose(np.asarray(rng.GetMin()), (ref.bounds @ scene.nav_from_scene.T).min(0), atol=1e-3)


def test_navmesh_gaussians_cameras_and_episode_starts(exported):
    from planners import NavMesh
    from pxr import Usd, UsdGeom

    from wanderland_nav.episodes.schema import load_episodes

    scene, out, summary = exported
    stage = Usd.Stage.Open(str(out))
    nm = NavMesh.load(scene.navmesh_path)
    nav = stage.GetPrimAtPath("/World/Scene/NavMesh")
    assert len(UsdGeom.Mesh(nav).GetFaceVertexCountsAttr().Get()) == len(nm.tris)
    idx = np.asarray(UsdGeom.Mesh(nav).GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    # scene frame: the navmesh's own triangles, corner for corner (USD stores float32 points). Not their centres'
    # heights: on terrain a big navmesh triangle's plane through its corner floors can leave the cell floor under
    # its centre by more than 0.6 m (the tiny demo: 0.67 m on a ramp), a property of the bake, not of the export
    np.testing.assert_array_equal(idx, nm.tris)
    local = torch.from_numpy(np.column_stack([nm.verts_xy, nm.verts_z]).astype(np.float64))
    np.testing.assert_allclose(_points(nav), nm.to_scene(local).numpy(), atol=1e-4)
    assert nm.is_navigable(_points(nav)[idx].mean(1), max_height_delta=4 * nm.ch).all()  # over its triangles
    g = stage.GetPrimAtPath("/World/Scene/Gaussians")
    api = UsdGeom.PrimvarsAPI(g)
    assert len(_points(g)) == summary["gaussians"] == 2000
    for name in ("scale_log", "rotation_wxyz", "opacity_logit", "sh_dc"):
        assert len(api.GetPrimvar(name).Get()) == 2000, name
    assert g.GetAttribute("wanderland:source").Get().path == str(scene.gaussians_path)
    cams = stage.GetPrimAtPath("/World/Scene/Cameras").GetChildren()
    assert len(cams) == len(scene.cameras)
    T0 = np.asarray(UsdGeom.Xformable(cams[0]).GetLocalTransformation()).T @ np.diag([1, -1, -1, 1])
    np.testing.assert_allclose(T0, scene.cameras[0].world_from_cam, atol=1e-9)
    eps = load_episodes(scene.episodes_path)
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Scene/EpisodeStarts"))
    np.testing.assert_allclose(np.asarray(inst.GetPositionsAttr().Get()), [e.start_position for e in eps], atol=1e-5)


def test_usdz_package_and_a_missing_collision_mesh(exported, tmp_path):
    import dataclasses

    from pxr import Usd

    from wanderland_nav.usd import export_scene_usd

    scene, _, _ = exported
    out = tmp_path / "s.usdz"
    export_scene_usd(scene, out)
    assert Usd.Stage.Open(str(out)).GetPrimAtPath("/World/Scene/Collision").IsValid()
    bare = dataclasses.replace(scene, collision_mesh_path=None)
    with pytest.raises(FileNotFoundError, match=r"no collision_mesh\.ply: run .*prepare"):
        export_scene_usd(bare, tmp_path / "x.usda")
    with pytest.raises(ValueError, match=r"must end in \.usda"):
        export_scene_usd(scene, tmp_path / "x.obj")
