"""Image-goal views: the splat render at the goal, at camera height, facing along the last path segment.

Why this pose: image-goal policies (NoMaD, CityWalker) are trained on the view the agent sees when it
arrives, which is the view along its final approach; rendering it with the same splat renderer as the
env keeps goal images and observations consistent. Cameras are batched through `render()`, on the env's
fused camera by default (`backend="fused"`, `render/fused.py`: the same image as the torch reference,
`backend="torch"`, which renders where the kernel cannot be built).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.geometry import agent_camera_poses, frustum_mask, invert_rigid, pinhole_intrinsics
from wanderland_nav.render.lod import DEFAULT_LOD_PX
from PIL import Image
from wanderland_nav.render import Gaussians, render
from wanderland_nav.render.lod import load_splat

log = logging.getLogger(__name__)


def goal_camera_poses(goals_nav: np.ndarray, yaws_nav: np.ndarray, nav_from_scene: np.ndarray, *,
                      height: float, pitch: float = 0.0) -> torch.Tensor:
    """`world_from_cam [N, 4, 4]` (scene frame, OpenCV) for cameras `height` m above `goals_nav [N, 3]`."""
    return agent_camera_poses(
        torch.as_tensor(np.asarray(goals_nav), dtype=torch.float64),
        torch.as_tensor(np.asarray(yaws_nav), dtype=torch.float64),
        height=height, pitch=pitch, nav_from_scene=np.asarray(nav_from_scene, dtype=np.float64),
    )


def render_goal_images(gaussians_path: Path, goals_nav: np.ndarray, yaws_nav: np.ndarray,
                       nav_from_scene: np.ndarray, out_paths: Sequence[Path], *, height: float,
                       width: int = 320, image_height: int = 240, hfov_deg: float = 90.0, pitch: float = 0.0,
                       batch: int = 8, lod_px: float | None = DEFAULT_LOD_PX, device: str = "cpu",
                       backend: str = "fused") -> list[Path | None]:
    """Render one PNG per goal into `out_paths` (atomic writes); returns the paths (all None, with a
    warning, when the scene has no Gaussians: `gaussians_path=None`).

    goals_nav `[N, 3]` feet positions (nav frame), yaws_nav `[N]` headings (rad). The splat is loaded
    once, at the camera's level of detail `lod_px` (`render.lod`; None: every Gaussian, frustum-culled
    per batch), and rendered `batch` cameras at a time (memory grows with C * H * W) by `render()`'s
    `backend` ("fused": one compiled call per batch; "torch": the reference; both give the same images).
    """


    if len(out_paths) != len(goals_nav):
        raise ValueError(f"render_goal_images: {len(goals_nav)} goals but {len(out_paths)} output paths")
    if gaussians_path is None:  # a LiDAR-only scene: episodes are still valid, they just carry no goal view
        log.warning("no 3dgs.ply in the scene: %d goal image(s) skipped (episodes get no goal_image)", len(out_paths))
        return [None] * len(out_paths)
    if not Path(gaussians_path).is_file():
        raise FileNotFoundError(f"{gaussians_path}: Gaussian splats (3dgs.ply) not found; needed for goal images "
                                "(set goal_images=false to skip them)")
    g = load_splat(gaussians_path, lod_px, device=device)
    world_from_cam = goal_camera_poses(goals_nav, yaws_nav, nav_from_scene, height=height, pitch=pitch)
    cam_from_world = invert_rigid(world_from_cam).to(device=device, dtype=torch.float32)  # [N, 4, 4]
    K = torch.as_tensor(pinhole_intrinsics(width, image_height, hfov_deg), dtype=torch.float32, device=device)
    written = []
    with torch.no_grad():
        for i in range(0, len(out_paths), batch):
            vm = cam_from_world[i:i + batch]
            Ks = K.expand(len(vm), 3, 3)
            if isinstance(g, Gaussians):  # every Gaussian: cull to the frustum first (~4x per view)
                out = render(g[frustum_mask(g.means, g.log_scales, vm, Ks, width, image_height)], vm, Ks, width,
                             image_height, render_mode="RGB", backend=backend)
            else:  # the hierarchy culls and cuts per view
                out = render(g, vm, Ks, width, image_height, render_mode="RGB", backend=backend)
            rgb = (out.rgb.clamp(0, 1) * 255).round().to(torch.uint8).cpu().numpy()  # [C, H, W, 3]
            for img, p in zip(rgb, out_paths[i:i + batch]):
                with atomic_path(p) as tmp:
                    Image.fromarray(img).save(tmp, format="PNG", optimize=False)
                written.append(Path(p))
    return written
