"""The README's picture: what the agent's camera sees at an episode start, beside the top-down map of the
navmesh with that episode's expert path.

    python experiments/front_page/figure.py [--scene data/scenes/demo] [--out docs/images/front_page.png]

Builds (or reuses) the procedural demo block the main job trains in, prepares its collision mesh and
navmesh, samples expert episodes with the main job's generator (seed 0) and picks the first one whose
shortest path bends (a straight path would show little of the planner). The camera frame is rendered by
the same `AgentCamera` the environment uses, from the episode's start facing the first leg of its expert
path, at `--size` px from all Gaussians (or the level of detail `--lod-px`; the main job trains at 32 px; the
picture is larger so it reads on a page). Prints the episode's id, geodesic length and path corners.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import matplotlib
import numpy as np
import torch

from planners import NavMesh
from wanderland_nav.envs.camera import AgentCamera
from wanderland_nav.envs.config import CameraConfig
from wanderland_nav.episodes.generate import GeneratorSettings, generate_episodes
from wanderland_nav.render import render
from wanderland_nav.render.lod import load_splat
from wanderland_nav.preparation.scene import ensure_demo_scene
from wanderland_nav.viz.topdown import plot_topdown

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)


def pick_episode(episodes, min_corners: int = 3, min_length: float = 15.0):
    """The first episode whose expert path has at least `min_corners` points and `min_length` metres."""
    for e in episodes:
        if len(e.reference_path) >= min_corners and e.geodesic_distance >= min_length:
            return e
    raise SystemExit(f"no episode with >= {min_corners} path corners and >= {min_length} m among {len(episodes)}")


def crop_margin(img: np.ndarray, pad: int = 4) -> np.ndarray:
    """`[H, W, C]` float image -> the same without its white margin (plot_topdown draws a square figure)."""
    ink = np.flatnonzero((img[..., :3] < 0.98).any(-1).any(0)), np.flatnonzero((img[..., :3] < 0.98).any(-1).any(1))
    (x0, x1), (y0, y1) = (ink[0][[0, -1]], ink[1][[0, -1]])
    return img[max(0, y0 - pad):y1 + pad + 1, max(0, x0 - pad):x1 + pad + 1]


def start_view(scene, episode, size: int, lod_px: float | None) -> np.ndarray:
    """-> uint8 `[size, size, 3]`: the agent camera at the episode start, facing along the first path leg."""
    R = np.asarray(scene.nav_from_scene, dtype=np.float64)  # scene -> nav frame (z up)
    path = np.asarray(episode.reference_path, dtype=np.float64)[:, :3] @ R.T  # [P, 3] nav frame
    leg = path[1, :2] - path[0, :2]
    yaw = float(np.arctan2(leg[1], leg[0]))
    cfg = dataclasses.replace(CameraConfig(), width=size, height=size)
    gaussians = load_splat(scene.gaussians_path, lod_px)
    cam = AgentCamera(cfg, scene.nav_from_scene, render, gaussians, "cpu")
    rgb, _ = cam.render(torch.as_tensor(path[:1], dtype=torch.float32), torch.tensor([yaw], dtype=torch.float32))
    return rgb[0].numpy()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=Path, default=Path("data/scenes/demo"))
    ap.add_argument("--out", type=Path, default=Path("docs/images/front_page.png"))
    ap.add_argument("--size", type=int, default=192)
    ap.add_argument("--lod-px", type=float, default=None, help="level of detail in pixels; default: all Gaussians")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    scene = ensure_demo_scene(a.scene)
    navmesh = NavMesh.load(scene.navmesh_path)
    episodes, _ = generate_episodes(scene, navmesh, num_episodes=20, seed=a.seed,
                                    settings=GeneratorSettings(goal_images=False))
    ep = pick_episode(episodes)
    frame = start_view(scene, ep, a.size, a.lod_px)

    with tempfile.TemporaryDirectory() as tmp:
        top = plot_topdown(Path(tmp) / "top.png", nav_from_scene=scene.nav_from_scene,
                           camera_centers=scene.capture_positions(), episodes=[ep], navmesh=navmesh,
                           title="navmesh, capture cameras and the expert path", dpi=100)
        top_img = crop_margin(plt.imread(top))
    fig, (ax_cam, ax_top) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [1, 1.9]})
    ax_cam.imshow(frame)
    ax_cam.set_title(f"agent camera at the start ({a.size} px, splat renderer)", fontsize=9)
    ax_top.imshow(top_img)
    ax_top.set_title(f"episode {ep.episode_id}: {ep.geodesic_distance:.1f} m geodesic", fontsize=9)
    for ax in (ax_cam, ax_top):
        ax.axis("off")
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=80, metadata={"Software": None})
    plt.close(fig)
    corners = len(ep.reference_path)
    print(f"episode {ep.episode_id}: geodesic {ep.geodesic_distance:.2f} m, {corners} path points; wrote {a.out}")


if __name__ == "__main__":
    main()
