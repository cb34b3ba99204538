"""Collision geometry the video-3DGS way: points fused from depth rendered out of the splats.

Video pipelines have no LiDAR: they extract their collision mesh from the 3DGS itself (TSDF or
depth fusion of rendered depth, or the opacity field). Here each capture pose renders expected depth
and accumulated opacity from the scene's `3dgs.ply` with the framework's own renderer; pixels with
enough opacity are back-projected into scene points, which then go through the same collision-mesh
extraction as the LiDAR cloud. Whatever the splats miss (thin or transparent parts, surfaces seen at
grazing angles, floaters) shows up in the mesh as it would in a video-built environment.

Every capture pose renders a virtual pinhole of the capture's focal length at `size` pixels on its
longer side (at most the capture's own; fisheye captures included: fusion needs depth at the pose, not the lens).
"""

from __future__ import annotations

import numpy as np
import torch

from wanderland_nav.render import render


def _virtual_K(K: np.ndarray, width: int, height: int, size: int) -> tuple[np.ndarray, int, int]:
    f = min(1.0, size / max(width, height))  # never render above the capture's own resolution
    w, h = max(1, round(width * f)), max(1, round(height * f))
    Kv = np.asarray(K, dtype=np.float64).copy()
    Kv[0, :] *= w / width
    Kv[1, :] *= h / height
    return Kv, w, h


def splat_depth_points(gaussians, cameras, *, size: int = 96, min_alpha: float = 0.5, cameras_per_call: int = 16,
                       device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Scene-frame points `[P,3]` float32 and colours `[P,3]` uint8 fused from rendered depth.

    `gaussians`: a `wanderland_nav.render.Gaussians` (scene frame); `cameras`: `scene.Camera`s.
    """
    if not cameras:
        raise ValueError("splat depth fusion needs capture cameras; the scene has none")
    g = gaussians.to(device)
    xyz_all, rgb_all = [], []
    groups: dict[tuple, list] = {}
    for cam in cameras:  # cameras of one image size render together (usually all of them)
        groups.setdefault((cam.width, cam.height), []).append(cam)
    for (W, H), cams in groups.items():
        for s in range(0, len(cams), cameras_per_call):
            chunk = cams[s:s + cameras_per_call]
            Ks, w, h = zip(*(_virtual_K(c.K, W, H, size) for c in chunk))
            w, h = w[0], h[0]
            viewmats = np.stack([c.cam_from_world for c in chunk])  # [C,4,4]
            with torch.no_grad():
                out = render(g, viewmats, np.stack(Ks), w, h, render_mode="RGB+ED")
            depth = out.depth[..., 0].cpu().numpy().astype(np.float64)  # [C,h,w] z-depth (OpenCV)
            alpha = out.alpha[..., 0].cpu().numpy()
            rgb = out.rgb.cpu().numpy()
            u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)  # pixel centres
            pix = np.stack([u, v, np.ones_like(u)], -1)  # [h,w,3]
            rays = np.einsum("cij,hwj->chwi", np.linalg.inv(np.stack(Ks)), pix)  # [C,h,w,3], z = 1
            T = np.stack([c.world_from_cam for c in chunk])  # [C,4,4]
            world = np.einsum("cij,chwj->chwi", T[:, :3, :3], rays * depth[..., None]) + T[:, None, None, :3, 3]
            ok = (alpha >= min_alpha) & np.isfinite(depth) & (depth > 0)  # [C,h,w]
            xyz_all.append(world[ok])
            rgb_all.append(rgb[ok])
    xyz = np.concatenate(xyz_all).astype(np.float32)
    rgb = (np.clip(np.concatenate(rgb_all), 0, 1) * 255 + 0.5).astype(np.uint8)
    return xyz, rgb
