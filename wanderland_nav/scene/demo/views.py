"""Pinhole images, depth and validity masks ray-cast from the textured ground-truth mesh.

For each pixel centre a ray leaves the camera; its first hit is shaded with the procedural
texture at that point, using the pixel footprint (distance x pixel angle / cos incidence) to
band-limit the texture, so distant brick walls average out instead of aliasing. Rays that miss
get the sky colour, depth 0 and mask 0. Depth is the z-depth along the optical axis (metres),
what a depth camera or a splat renderer's "ED"/"D" output reports.
"""

from __future__ import annotations

import numpy as np

from . import textures
from .layout import Layout
from .raycast import RayCaster


def pixel_rays(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Unit ray directions `[H*W, 3]` in the camera frame (OpenCV axes), row-major pixel order."""
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    d = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).reshape(-1, 3)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def render_views(caster: RayCaster, layout: Layout, world_from_cam: np.ndarray, K: np.ndarray, width: int,
                 height: int, seed: int, batch: int = 16):
    """Ray-cast `C` views. `world_from_cam [C, 4, 4]` nav frame, OpenCV axes.

    Returns `rgb [C, H, W, 3] uint8`, `depth [C, H, W] float32` (z-depth, 0 = no hit),
    `mask [C, H, W] uint8` (255 = geometry, 0 = sky) and the set of hit triangle ids.
    """
    C = world_from_cam.shape[0]
    d_cam = pixel_rays(K, width, height)  # [HW, 3]
    pix_angle = 1.0 / K[0, 0]
    rgb = np.empty((C, height, width, 3), np.uint8)
    depth = np.empty((C, height, width), np.float32)
    mask = np.empty((C, height, width), np.uint8)
    seen = []
    for a in range(0, C, batch):
        T = world_from_cam[a:a + batch]  # [c, 4, 4]
        c = T.shape[0]
        dirs = np.einsum("cij,nj->cni", T[:, :3, :3], d_cam).reshape(-1, 3)  # [c*HW, 3]
        orig = np.repeat(T[:, :3, 3], d_cam.shape[0], axis=0)
        t, tri = caster.cast(orig, dirs)
        hit = tri >= 0
        col = textures.sky(dirs)
        h = np.flatnonzero(hit)
        p = orig[h] + t[h, None] * dirs[h]
        n = caster.normals[tri[h]]
        cosi = np.abs(np.einsum("ni,ni->n", n, dirs[h]))
        fw = t[h] * pix_angle / np.maximum(cosi, 0.15)
        col[h] = textures.shade(layout.face_material[tri[h]], p, n, fw, layout.is_indoor(p), seed, layout.car_color)
        z = np.where(hit, t * np.tile(d_cam[:, 2], c), 0.0)
        rgb[a:a + c] = np.round(col * 255.0).astype(np.uint8).reshape(c, height, width, 3)
        depth[a:a + c] = z.reshape(c, height, width)
        mask[a:a + c] = np.where(hit, 255, 0).astype(np.uint8).reshape(c, height, width)
        seen.append(np.unique(tri[h]))
    return rgb, depth, mask, np.unique(np.concatenate(seen)) if seen else np.zeros(0, np.int64)
