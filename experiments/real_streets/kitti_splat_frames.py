"""Agent camera frames rendered from a LiDAR-only street's `lidar_splat` (`wanderland_nav/scene/lidar_splat.py`).

    PYTHONPATH=$PWD python experiments/real_streets/kitti_splat_frames.py --scene /tmp/kitti_street \
        [--build] [--png experiments/real_streets/kitti_splat_frames.png] [--size 128]

`--build` first makes the KITTI v2 folder (`kitti_street.make_scene`) and its splat (`write_lidar_splat`). Then
one frame per sensor pose, with the agent's feet `SENSOR_HEIGHT` under the sensor looking along the
trajectory, plus the same poses looking 90 deg left: the default env camera (`conf/env`: pinhole, hfov 90,
1.2 m above the feet, pitched 10 deg down), at `--size` pixels. The frames are false colour (grey =
ground by LiDAR intensity, orange -> blue = height above the ground), NOT photographs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from kitti_street import SENSOR_HEIGHT, make_scene  # noqa: E402


def render_frames(root: Path, size: int) -> tuple[np.ndarray, list[str]]:
    """-> uint8 frames [F, size, size, 3] and their titles."""
    from wanderland_nav.envs.camera import AgentCamera
    from wanderland_nav.envs.config import CameraConfig
    from wanderland_nav.render import Gaussians, render
    from wanderland_nav.scene import load_scene

    scene = load_scene(root)
    cfg = dataclasses.replace(CameraConfig(), width=size, height=size, render_threads=1)
    cam = AgentCamera(cfg, scene.nav_from_scene, render, Gaussians.load(scene.gaussians_path), "cpu")
    path = scene.capture_positions() @ scene.nav_from_scene.T  # [K,3] sensor positions, nav frame
    step = np.gradient(path[:, :2], axis=0)
    yaw = np.arctan2(step[:, 1], step[:, 0])
    feet = path - [0.0, 0.0, SENSOR_HEIGHT]
    pos = torch.as_tensor(np.concatenate([feet, feet]), dtype=torch.float32)
    yaws = torch.as_tensor(np.concatenate([yaw, yaw + np.pi / 2]), dtype=torch.float32)
    rgb, _ = cam.render(pos, yaws)
    titles = [f"pose {i} {'ahead' if j == 0 else 'left'}" for j in range(2) for i in range(len(path))]
    return rgb.numpy(), titles


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=Path, default=Path("/tmp/kitti_street"))
    ap.add_argument("--build", action="store_true")
    ap.add_argument("--png", type=Path, default=Path(__file__).with_name("kitti_splat_frames.png"))
    ap.add_argument("--size", type=int, default=128)
    a = ap.parse_args(argv)
    if a.build:
        from wanderland_nav.scene.lidar_splat import write_lidar_splat

        make_scene(a.scene)
        print(write_lidar_splat(a.scene))
    frames, titles = render_frames(a.scene, a.size)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = len(frames) // 2
    fig, axes = plt.subplots(2, cols, figsize=(2.2 * cols, 4.8))
    for ax, f, t in zip(axes.ravel(), frames, titles):
        ax.imshow(f)
        ax.set_title(t, fontsize=8)
        ax.axis("off")
    fig.suptitle("KITTI street, agent camera on the lidar_splat (false colour from LiDAR, not photographic)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(a.png, dpi=110)
    print(f"wrote {a.png}: {len(frames)} frames, mean brightness {frames.mean():.1f}/255, "
          f"share of background pixels {(frames.max(-1) == 0).mean():.2f}")


if __name__ == "__main__":
    sys.exit(main())
