"""One scene as a USD stage (`usd-core`), so the same geometry loads in Isaac Sim.

Layout (every prim under `/World/Scene` keeps **scene-frame** coordinates, metres):

    /World                      Xform, the stage's default prim
    /World/Scene                Xform whose transform is nav_from_scene (identity for +z scenes), so
                                the stage is Z-up for every scene frame (v1 COLMAP is -y up)
        Collision               Mesh, UsdPhysics.CollisionAPI + MeshCollisionAPI, invisible
        NavMesh                 Mesh, walkable triangles, per-face primvar `island`
        Gaussians               Points: widths, displayColor and the raw 3DGS parameters as primvars
                                (scale_log float3, rotation_wxyz float4, opacity_logit, sh_dc float3,
                                sh_rest float[] of elementSize 3*(K-1)); `wanderland:source` = 3dgs.ply
        Cameras/<i>             Camera per capture camera (USD camera axes: -z forward, +y up), with
                                `wanderland:K`, `wanderland:distortion`, `wanderland:model`
        EpisodeStarts           PointInstancer: one arrow per episode start (position, heading)

USD supports only Y- or Z-up stages: `upAxis` is Z and `metersPerUnit` 1.0; the scene-to-stage rotation
lives in one place (the `/World/Scene` transform), so episodes (scene frame, VLN-CE-Isaac schema) line
up with every prim below it without conversion.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.render import Gaussians

log = logging.getLogger(__name__)

_GL_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes -> USD/OpenGL camera axes


def _mat(T: np.ndarray):
    from pxr import Gf

    return Gf.Matrix4d(np.asarray(T, dtype=np.float64).T.tolist())  # USD matrices are row-vector (transposed)


def _mesh(stage, path: str, verts: np.ndarray, faces: np.ndarray):
    from pxr import UsdGeom, Vt

    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(verts, dtype=np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces, dtype=np.int32).ravel()))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if len(verts):
        m.CreateExtentAttr([tuple(map(float, verts.min(0))), tuple(map(float, verts.max(0)))])
    return m


def add_collision_mesh(stage, path: str, verts: np.ndarray, faces: np.ndarray) -> None:
    """Collision geometry: physics collider (triangle mesh, no approximation), invisible for rendering."""
    from pxr import UsdPhysics

    m = _mesh(stage, path, verts, faces)
    UsdPhysics.CollisionAPI.Apply(m.GetPrim())
    UsdPhysics.MeshCollisionAPI.Apply(m.GetPrim()).CreateApproximationAttr("none")
    m.MakeInvisible()


def add_navmesh(stage, path: str, navmesh) -> None:
    """The walkable triangles (scene frame) with a per-face `island` primvar."""
    from pxr import Sdf, UsdGeom, Vt

    local = np.column_stack([navmesh.verts_xy, navmesh.verts_z]).astype(np.float64)
    verts = navmesh.to_scene(torch.from_numpy(local)).numpy()
    m = _mesh(stage, path, verts, np.asarray(navmesh.tris))
    pv = UsdGeom.PrimvarsAPI(m).CreatePrimvar("island", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.uniform)
    pv.Set(Vt.IntArray.FromNumpy(np.asarray(navmesh.tri_island, dtype=np.int32)))


def add_gaussians(stage, path: str, ply_path: Path, max_gaussians: int | None = None) -> int:
    """The splats as a Points prim with their raw parameters as primvars; returns how many were written."""
    from pxr import Sdf, UsdGeom, Vt


    g = Gaussians.load(ply_path)
    if max_gaussians is not None and len(g) > max_gaussians:  # evenly spaced subset, said in the log
        log.warning("%s: %d Gaussians, exporting %d (max_gaussians)", ply_path, len(g), max_gaussians)
        g = g[torch.linspace(0, len(g) - 1, max_gaussians).long()]
    n = len(g)
    p = UsdGeom.Points.Define(stage, path)
    f32 = lambda t: np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)  # noqa: E731
    means = f32(g.means)
    p.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(means))
    p.CreateWidthsAttr(Vt.FloatArray.FromNumpy(2.0 * f32(g.log_scales.exp().amax(-1))))  # 1-sigma diameter
    if n:
        p.CreateExtentAttr([tuple(map(float, means.min(0))), tuple(map(float, means.max(0)))])
    api = UsdGeom.PrimvarsAPI(p)
    rgb = np.clip(0.5 + 0.28209479177387814 * f32(g.sh_dc), 0.0, 1.0)  # SH degree-0 colour
    p.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set(Vt.Vec3fArray.FromNumpy(rgb))
    T = Sdf.ValueTypeNames
    for name, vtype, arr in (("scale_log", T.Float3Array, Vt.Vec3fArray.FromNumpy(f32(g.log_scales))),
                             ("rotation_wxyz", T.Float4Array, Vt.Vec4fArray.FromNumpy(f32(g.quats))),
                             ("opacity_logit", T.FloatArray, Vt.FloatArray.FromNumpy(f32(g.opacity_logits))),
                             ("sh_dc", T.Float3Array, Vt.Vec3fArray.FromNumpy(f32(g.sh_dc)))):
        api.CreatePrimvar(name, vtype, UsdGeom.Tokens.vertex).Set(arr)
    rest = f32(g.sh_rest).reshape(n, -1)  # [N, 3*(K-1)], coefficient-major, channel-minor
    if rest.shape[1]:
        pv = api.CreatePrimvar("sh_rest", T.FloatArray, UsdGeom.Tokens.vertex, rest.shape[1])
        pv.Set(Vt.FloatArray.FromNumpy(rest.ravel()))
    p.GetPrim().CreateAttribute("wanderland:source", T.Asset).Set(Sdf.AssetPath(str(ply_path)))
    return n


def add_cameras(stage, path: str, cameras) -> None:
    """One UsdGeom.Camera per capture camera; intrinsics kept exactly as custom attributes."""
    from pxr import Gf, Sdf, UsdGeom

    UsdGeom.Scope.Define(stage, path)
    for i, c in enumerate(cameras):  # capture cameras: hundreds at most, each its own prim
        cam = UsdGeom.Camera.Define(stage, f"{path}/cam_{i:05d}")
        UsdGeom.Xformable(cam).AddTransformOp().Set(_mat(np.asarray(c.world_from_cam) @ _GL_FROM_CV))
        focal = 10.0  # aperture and focal length share units (tenths of a scene unit); only ratios matter
        cam.CreateFocalLengthAttr(focal)
        cam.CreateHorizontalApertureAttr(focal * c.width / float(c.K[0, 0]))
        cam.CreateVerticalApertureAttr(focal * c.height / float(c.K[1, 1]))
        prim = cam.GetPrim()
        prim.CreateAttribute("wanderland:name", Sdf.ValueTypeNames.String).Set(str(c.name))
        prim.CreateAttribute("wanderland:model", Sdf.ValueTypeNames.String).Set(str(c.camera_model))
        prim.CreateAttribute("wanderland:K", Sdf.ValueTypeNames.Matrix3d).Set(
            Gf.Matrix3d(np.asarray(c.K, dtype=np.float64).tolist()))
        prim.CreateAttribute("wanderland:distortion", Sdf.ValueTypeNames.DoubleArray).Set(
            [float(d) for d in np.asarray(c.distortion).ravel()])
        prim.CreateAttribute("wanderland:split", Sdf.ValueTypeNames.String).Set(str(c.split))


def add_episode_starts(stage, path: str, episodes, nav_from_scene: np.ndarray) -> None:
    """A PointInstancer of arrows at every episode start: the cone points along the agent's forward
    (nav +x in the scene frame, turned by the start rotation: `schema.yaw_from_rotation`)."""
    from pxr import Gf, UsdGeom, Vt

    inst = UsdGeom.PointInstancer.Define(stage, path)
    proto = UsdGeom.Cone.Define(stage, f"{path}/Prototypes/Arrow")
    proto.CreateAxisAttr("X")
    T = np.eye(4)
    T[:3, :3] = np.asarray(nav_from_scene, dtype=np.float64).T  # cone +X (nav forward) -> scene frame
    UsdGeom.Xformable(proto).AddTransformOp().Set(_mat(T))
    proto.CreateRadiusAttr(0.15)
    proto.CreateHeightAttr(0.5)
    inst.CreatePrototypesRel().SetTargets([proto.GetPath()])
    pos = np.array([e.start_position for e in episodes], dtype=np.float32).reshape(-1, 3)
    q = np.array([e.start_rotation_wxyz for e in episodes], dtype=np.float64).reshape(-1, 4)
    inst.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(pos))
    inst.CreateOrientationsAttr([Gf.Quath(float(w), float(x), float(y), float(z)) for w, x, y, z in q])
    inst.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(len(pos), np.int32)))
    inst.CreateIdsAttr(Vt.Int64Array.FromNumpy(np.array([int(e.episode_id) for e in episodes], np.int64)))
