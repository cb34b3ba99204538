"""Agent camera frames rendered from a LiDAR-only street's `lidar_splat` (`wanderland_nav/scene/lidar_splat.py`).

    python experiments/real_streets/kitti_street.py --scene <dir>/kitti_street      # the scene folder, prepared
    python experiments/real_streets/kitti_splat_frames.py --scene <dir>/kitti_street [--build] \
        [--more <degraded scene> ...] [--png experiments/real_streets/kitti_splat_frames.png] [--size 128] \
        [--lod-px 1]

`--build` first writes the street's splat (`write_lidar_splat`). Then,
per scene (the street and each `--more` one, e.g. the study's degraded copies), one frame at every other sensor
pose, with the agent's feet `SENSOR_HEIGHT` (times the scene's degradation scale) under the sensor looking along
the trajectory, and the same poses looking 90 deg left: the default env camera (`conf/env`: pinhole, hfov 90,
1.2 m above the feet, pitched 10 deg down) at `--size` pixels, from the `--lod-px` level of detail
(`train`'s `render.lod_px`; the citywalker policy sees 32 x 32). False colour (grey = ground by LiDAR
intensity, orange -> blue = height above the ground), NOT photographs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.render.lod import DEFAULT_LOD_PX

SENSOR_HEIGHT = 1.73  # metres from the KITTI Velodyne to the road (the dataset's sensor setup)


def render_frames(root: Path, size: int, lod_px: float | None) -> tuple[np.ndarray, list[str]]:
    """-> uint8 frames [F, size, size, 3] and their titles."""
    import json

    from wanderland_nav.envs.camera import AgentCamera
    from wanderland_nav.envs.config import CameraConfig
    from wanderland_nav.render import Gaussians, render
    from wanderland_nav.render.lod import load_splat
    from wanderland_nav.scene import load_scene

    scene = load_scene(root)
    scale = (json.loads((root / "scene_meta.json").read_text()).get("degradation") or {}).get("spec", {}).get("scale", 1)
    cfg = dataclasses.replace(CameraConfig(), width=size, height=size, render_threads=1)
    g = load_splat(scene.gaussians_path, lod_px)
    cam = AgentCamera(cfg, scene.nav_from_scene, render, g, "cpu")
    path = scene.capture_positions() @ scene.nav_from_scene.T  # [K,3] sensor positions, nav frame
    step = np.gradient(path[:, :2], axis=0)
    pick = np.arange(0, len(path), 2)
    yaw = np.arctan2(step[pick, 1], step[pick, 0])
    feet = path[pick] - [0.0, 0.0, SENSOR_HEIGHT * scale]
    pos = torch.as_tensor(np.concatenate([feet, feet]), dtype=torch.float32)
    yaws = torch.as_tensor(np.concatenate([yaw, yaw + np.pi / 2]), dtype=torch.float32)
    rgb, _ = cam.render(pos, yaws)
    titles = [f"{scene.name.split('__')[-1]} pose {i} {'ahead' if j == 0 else 'left'}" for j in range(2) for i in pick]
    return rgb.numpy(), titles


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=Path, default=Path("/tmp/kitti_street"))
    ap.add_argument("--build", action="store_true")
    ap.add_argument("--png", type=Path, default=Path(__file__).with_name("kitti_splat_frames.png"))
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--lod-px", type=lambda v: None if v == "none" else float(v), default=DEFAULT_LOD_PX)
    ap.add_argument("--more", type=Path, nargs="*", default=[])
    a = ap.parse_args(argv)
    if a.build:
        from wanderland_nav.scene.lidar_splat import write_lidar_splat

        print(write_lidar_splat(a.scene))
    rows = [render_frames(root, a.size, a.lod_px) for root in [a.scene, *a.more]]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = len(rows[0][0])
    fig, axes = plt.subplots(len(rows), cols, figsize=(2.2 * cols, 2.4 * len(rows) + 0.4), squeeze=False)
    for ax_row, (frames, titles) in zip(axes, rows):
        for ax, f, t in zip(ax_row, frames, titles):
            ax.imshow(f)
            ax.set_title(t, fontsize=7)
            ax.axis("off")
    fig.suptitle(f"KITTI street, agent camera on the lidar_splat ({a.size} px, level of detail {a.lod_px} px): false "
                 "colour from LiDAR, not photographic", fontsize=9)
    fig.tight_layout()
    fig.savefig(a.png, dpi=110)
    for frames, titles in rows:
        print(f"{titles[0].split(' pose')[0]}: {len(frames)} frames, mean brightness {frames.mean():.1f}/255, "
              f"background (black) pixels {(frames.max(-1) == 0).mean():.2f}")
    print(f"wrote {a.png}")


if __name__ == "__main__":
    sys.exit(main())
