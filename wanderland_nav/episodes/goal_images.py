"""Image-goal views: the splat render at the goal, at camera height, facing along the last path segment.

Why this pose: image-goal policies (NoMaD, CityWalker) are trained on the view the agent sees when it
arrives, which is the view along its final approach; rendering it with the same splat renderer as the
env keeps goal images and observations consistent. Cameras are batched through `render()`.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.geometry import agent_camera_poses, invert_rigid

log = logging.getLogger(__name__)


def pinhole_K(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """`[3, 3]` intrinsics with square pixels and the principal point at the image centre."""
    if not (0 < hfov_deg < 180):
        raise ValueError(f"goal image hfov_deg must be in (0, 180), got {hfov_deg}")
    f = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], dtype=np.float64)


def goal_camera_poses(goals_nav: np.ndarray, yaws_nav: np.ndarray, nav_from_scene: np.ndarray, *,
                      height: float, pitch: float = 0.0) -> torch.Tensor:
    """`world_from_cam [N, 4, 4]` (scene frame, OpenCV) for cameras `height` m above `goals_nav [N, 3]`."""
    return agent_camera_poses(
        torch.as_tensor(np.asarray(goals_nav), dtype=torch.float64),
        torch.as_tensor(np.asarray(yaws_nav), dtype=torch.float64),
        height=height, pitch=pitch, nav_from_scene=np.asarray(nav_from_scene, dtype=np.float64),
    )


def frustum_mask(means: torch.Tensor, radius: torch.Tensor, cam_from_world: torch.Tensor, hfov_deg: float,
                 vfov_deg: float, near: float = 0.01) -> torch.Tensor:
    """`bool [G]`: Gaussians whose 3-sigma sphere may touch any of the `[C, 4, 4]` view frusta.

    The CPU renderer's cost grows with the number of Gaussians it projects and composites, and a
    90-degree view sees about a quarter of a scene, so culling first is a ~4x saving per view. The
    test is conservative (sphere vs the four side planes), so no visible splat is ever dropped.
    """
    p = means @ cam_from_world[:, :3, :3].transpose(-1, -2) + cam_from_world[:, None, :3, 3]  # [C, G, 3] camera frame
    x, y, z = p.unbind(-1)
    r = radius[None]
    th, tv = math.radians(hfov_deg) / 2, math.radians(vfov_deg) / 2
    # signed distance to each side plane through the optical centre (inside > 0)
    ch, sh, cv, sv = math.cos(th), math.sin(th), math.cos(tv), math.sin(tv)
    inside = (z > near - r)
    inside &= (z * sh - x * ch > -r) & (z * sh + x * ch > -r)
    inside &= (z * sv - y * cv > -r) & (z * sv + y * cv > -r)
    return inside.any(0)


def render_goal_images(gaussians_path: Path, goals_nav: np.ndarray, yaws_nav: np.ndarray,
                       nav_from_scene: np.ndarray, out_paths: Sequence[Path], *, height: float,
                       width: int = 320, image_height: int = 240, hfov_deg: float = 90.0, pitch: float = 0.0,
                       batch: int = 8, device: str = "cpu") -> list[Path | None]:
    """Render one PNG per goal into `out_paths` (atomic writes); returns the paths (all None, with a
    warning, when the scene has no Gaussians: `gaussians_path=None`).

    goals_nav `[N, 3]` feet positions (nav frame), yaws_nav `[N]` headings (rad). The Gaussians are
    loaded once and rendered `batch` cameras at a time (memory grows with C * H * W).
    """
    from PIL import Image

    from wanderland_nav.render import Gaussians, render

    if len(out_paths) != len(goals_nav):
        raise ValueError(f"render_goal_images: {len(goals_nav)} goals but {len(out_paths)} output paths")
    if gaussians_path is None:  # a LiDAR-only scene: episodes are still valid, they just carry no goal view
        log.warning("no 3dgs.ply in the scene: %d goal image(s) skipped (episodes get no goal_image)", len(out_paths))
        return [None] * len(out_paths)
    if not Path(gaussians_path).is_file():
        raise FileNotFoundError(f"{gaussians_path}: Gaussian splats (3dgs.ply) not found; needed for goal images "
                                "(set goal_images=false to skip them)")
    g = Gaussians.load(gaussians_path).to(device)
    world_from_cam = goal_camera_poses(goals_nav, yaws_nav, nav_from_scene, height=height, pitch=pitch)
    cam_from_world = invert_rigid(world_from_cam).to(device=device, dtype=torch.float32)  # [N, 4, 4]
    K = torch.as_tensor(pinhole_K(width, image_height, hfov_deg), dtype=torch.float32, device=device)
    vfov = 2 * math.atan(math.tan(math.radians(hfov_deg) / 2) * image_height / width)
    written = []
    with torch.no_grad():
        radius = 3.0 * g.log_scales.exp().amax(-1)  # [G] 3-sigma extent, for conservative culling
        for i in range(0, len(out_paths), batch):
            vm = cam_from_world[i:i + batch]
            keep = frustum_mask(g.means, radius, vm, hfov_deg, math.degrees(vfov))
            out = render(g[keep], vm, K.expand(len(vm), 3, 3), width, image_height, render_mode="RGB")
            rgb = (out.rgb.clamp(0, 1) * 255).round().to(torch.uint8).cpu().numpy()  # [C, H, W, 3]
            for img, p in zip(rgb, out_paths[i:i + batch]):
                with atomic_path(p) as tmp:
                    Image.fromarray(img).save(tmp, format="PNG", optimize=False)
                written.append(Path(p))
    return written
