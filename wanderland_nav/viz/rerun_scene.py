"""Log a scene to rerun: collision mesh, navmesh coloured by island, a point-cloud subsample and the
capture cameras as pinhole frustums (with their images when present).

Everything is logged in the scene's **native frame** under `world/`, with `world` tagged by the
`ViewCoordinates` of the scene's up axis, so the viewer's "up" is gravity's opposite whatever the
dataset's convention (v1 COLMAP -y, v2 +z, Recast +y). All of it is static (no timeline).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import torch
from PIL import Image

from planners import NavMesh
from wanderland_nav.scene.collision import load_collision_mesh

_VIEW_COORDS = {
    "+x": rr.ViewCoordinates.RIGHT_HAND_X_UP, "-x": rr.ViewCoordinates.RIGHT_HAND_X_DOWN,
    "+y": rr.ViewCoordinates.RIGHT_HAND_Y_UP, "-y": rr.ViewCoordinates.RIGHT_HAND_Y_DOWN,
    "+z": rr.ViewCoordinates.RIGHT_HAND_Z_UP, "-z": rr.ViewCoordinates.RIGHT_HAND_Z_DOWN,
}

# a qualitative palette (tab10) for islands; island i gets _PALETTE[i % 10]
_PALETTE = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
                     [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207]], np.uint8)


def view_coordinates(up_axis: str):
    """rerun `ViewCoordinates` for a scene whose up axis is `up_axis` ("+x" ... "-z")."""
    try:
        return _VIEW_COORDS[up_axis]
    except KeyError:
        raise ValueError(f"up_axis={up_axis!r}: expected one of {sorted(_VIEW_COORDS)}") from None


def island_colors(island: np.ndarray) -> np.ndarray:
    """uint8 `[..., 3]` colour per island id (`-1` -> grey)."""
    island = np.asarray(island)
    return np.where((island >= 0)[..., None], _PALETTE[np.maximum(island, 0) % len(_PALETTE)], np.uint8(90))


def navmesh_triangles_scene(navmesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`(vertices [V,3] scene frame, triangles [T,3] int, tri_island [T])` of a `planners.NavMesh`.

    The navmesh stores its polygons in a local z-up frame relative to `bmin` (`verts_xy`, `verts_z`,
    metres); `to_scene` maps them back to the scene frame the rest of the recording uses.
    """
    local = np.concatenate([navmesh.verts_xy, navmesh.verts_z[:, None]], -1)
    verts = navmesh.to_scene(torch.as_tensor(local, dtype=torch.float64)).numpy().astype(np.float32)
    return verts, np.asarray(navmesh.tris, np.int64), np.asarray(navmesh.tri_island, np.int64)


def log_navmesh(rec: rr.RecordingStream, navmesh, path: str = "world/navmesh", lift: float = 0.03) -> None:
    """Navmesh triangles coloured by island. Vertices are split per triangle (`[T*3]`) so each face
    takes its island's colour; lifted `lift` metres along up so they don't z-fight the collision mesh."""
    verts, tris, isl = navmesh_triangles_scene(navmesh)
    if len(tris) == 0:
        return
    up = np.asarray(navmesh.nav_from_scene, np.float64)[2]  # nav +z expressed in the scene frame
    pos = verts[tris].reshape(-1, 3) + (lift * up).astype(np.float32)  # [T*3, 3]
    cols = np.repeat(island_colors(isl), 3, axis=0)  # [T*3, 3]
    rec.log(path, rr.Mesh3D(vertex_positions=pos, triangle_indices=np.arange(len(pos)).reshape(-1, 3),
                            vertex_colors=cols), static=True)


def log_collision_mesh(rec: rr.RecordingStream, mesh_path: str | Path, path: str = "world/collision_mesh") -> None:
    mesh = load_collision_mesh(mesh_path)
    rec.log(path, rr.Mesh3D(vertex_positions=np.asarray(mesh.vertices, np.float32),
                            triangle_indices=np.asarray(mesh.faces, np.int64),
                            vertex_normals=np.asarray(mesh.vertex_normals, np.float32),
                            albedo_factor=[0.75, 0.75, 0.78, 1.0]), static=True)


def log_points(rec: rr.RecordingStream, points: np.ndarray, colors: np.ndarray | None, *, max_points: int,
               seed: int = 0, path: str = "world/points") -> int:
    """A seeded uniform subsample of at most `max_points` points; returns how many were logged."""
    n = len(points)
    if n == 0 or max_points <= 0:
        return 0
    idx = np.sort(np.random.default_rng(seed).choice(n, size=min(n, max_points), replace=False))
    rec.log(path, rr.Points3D(points[idx], colors=None if colors is None else colors[idx], radii=0.02), static=True)
    return len(idx)


def log_camera(rec: rr.RecordingStream, path: str, world_from_cam: np.ndarray, K: np.ndarray, width: int,
               height: int, *, image: np.ndarray | None = None, static: bool = True,
               plane_distance: float = 0.3) -> None:
    """One OpenCV-axes camera: transform (parent <- cam), pinhole frustum, optional image `[H, W, 3]`."""
    T = np.asarray(world_from_cam, np.float64)
    rec.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=static)
    rec.log(path, rr.Pinhole(image_from_camera=np.asarray(K, np.float32), resolution=[width, height],
                             camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=plane_distance), static=static)
    if image is not None:
        rec.log(path, rr.Image(image), static=static)


def log_capture_cameras(rec: rr.RecordingStream, cameras, *, max_cameras: int = 64, images: bool = True,
                        image_max_side: int = 256, path: str = "world/capture") -> int:
    """Up to `max_cameras` capture cameras (evenly spaced over the list), each `path/<name>`; images are
    read from disk and downscaled to `image_max_side` to keep the recording small. Returns the count."""
    if not cameras:
        return 0
    sel = np.unique(np.linspace(0, len(cameras) - 1, min(len(cameras), max_cameras)).round().astype(int))
    for i in sel:  # a loop over a few dozen cameras (I/O bound), not a hot path
        c = cameras[i]
        img = None
        if images and c.image_path is not None and Path(c.image_path).is_file():
            img = _load_image(Path(c.image_path), image_max_side)
        K, w, h = np.asarray(c.K, np.float64).copy(), int(c.width), int(c.height)
        if img is not None and img.shape[1] != w:  # downscaled: scale the intrinsics with the image
            s = img.shape[1] / w
            K[:2] *= s
            w, h = img.shape[1], img.shape[0]
        name = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in Path(c.name).stem)
        log_camera(rec, f"{path}/{name}", c.world_from_cam, K, w, h, image=img)
    return len(sel)


def _load_image(p: Path, max_side: int) -> np.ndarray:
    with Image.open(p) as im:
        im = im.convert("RGB")
        s = max_side / max(im.size)
        if s < 1:
            im = im.resize((max(1, round(im.width * s)), max(1, round(im.height * s))), Image.BILINEAR)
        return np.asarray(im)


def log_scene(rec: rr.RecordingStream, scene, *, navmesh=None, max_points: int = 50_000, max_cameras: int = 64,
              camera_images: bool = True, seed: int = 0) -> dict:
    """Everything static about `scene` under `world/`; returns counts of what was logged.

    navmesh: a `planners.NavMesh`, or None to load `scene.navmesh_path` when it exists.
    """
    rec.log("world", view_coordinates(scene.up_axis), static=True)
    out = {"points": log_points(rec, np.asarray(scene.points), np.asarray(scene.colors) if scene.colors is not None
                                else None, max_points=max_points, seed=seed)}
    if scene.collision_mesh_path is not None and Path(scene.collision_mesh_path).is_file():
        log_collision_mesh(rec, scene.collision_mesh_path)
        out["collision_mesh"] = 1
    if navmesh is None and scene.navmesh_path is not None and Path(scene.navmesh_path).is_file():
        navmesh = NavMesh.load(scene.navmesh_path)
    if navmesh is not None:
        log_navmesh(rec, navmesh)
        out["navmesh_triangles"] = int(len(navmesh.tris))
    out["cameras"] = log_capture_cameras(rec, scene.cameras, max_cameras=max_cameras, images=camera_images)
    return out
