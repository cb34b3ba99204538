"""Replay a rollout or expert paths into a rerun recording.

    python -m wanderland_nav.replay rollout=<file> out=<file.rrd>

* `rollout=<file.npz>` (from `evaluate ... save_rollouts=<file.npz>`): the scene (collision mesh,
  navmesh by island, points, capture cameras), the episodes the agents ran, and per step each agent's
  pose, camera image, predicted waypoints, reward, distance to goal and finished-episode metrics.
  Frames not stored in the file are re-rendered from the scene's splats with the recorded camera.
* `episodes=<episodes.json>`: the scene and the episodes, and the expert's camera rendered along
  each `gt_locations` path (one agent playing the episodes one after another).
* `viewer=true` opens the rerun viewer on the result when one is available.

Thin by design: it resolves files and calls `wanderland_nav.rollouts` / `wanderland_nav.viz.recording`.
"""

from __future__ import annotations

import time
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from wanderland_nav.rollouts import expert_rollout, load_rollout, render_rollout_frames


def _load_gaussians(scene, max_gaussians):
    """The scene's Gaussians, or training's level-of-detail subset (same selection as `render.max_gaussians`)."""
    if scene is None or scene.gaussians_path is None or not Path(scene.gaussians_path).is_file():
        return None
    if max_gaussians is not None:
        try:
            from wanderland_nav.rl.policy_env import lod_gaussians
        except ImportError:  # older trainer layout: the helper lived in train.py
            from wanderland_nav.train import render_gaussians

            return render_gaussians(scene, int(max_gaussians))
        return lod_gaussians(scene.gaussians_path, int(max_gaussians))
    from wanderland_nav.render import Gaussians

    return Gaussians.load(scene.gaussians_path)


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests). Returns the logged counts + `out`."""
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene import load_scene
    from wanderland_nav.viz.recording import open_viewer, write_recording

    if cfg.rollout is None and cfg.episodes is None:
        raise ValueError("replay: give rollout=<file.npz> and/or episodes=<episodes.json>")
    t0 = time.perf_counter()
    rollout = load_rollout(cfg.rollout) if cfg.rollout is not None else None
    src = Path(cfg.rollout if cfg.rollout is not None else cfg.episodes)
    root = cfg.scene_path or (rollout.meta.scene_root if rollout is not None else None) or \
        (str(Path(cfg.episodes).parent) if cfg.episodes is not None else None)
    scene = None
    if root is not None:
        if not Path(root).is_dir():
            where = "scene_path" if cfg.scene_path else f"{src}: meta_json.scene_root"
            raise FileNotFoundError(f"{where}={root}: no such scene folder (pass scene_path=<folder>)")
        scene = load_scene(root)
    ep_path = cfg.episodes or (rollout.meta.episodes_path if rollout is not None else None)
    episodes = load_episodes(ep_path) if ep_path and Path(ep_path).is_file() else []

    if rollout is None:  # expert replay: camera along the episodes' paths
        if scene is None:
            raise FileNotFoundError(f"episodes={cfg.episodes}: its scene folder is needed (scene_path=<folder>)")
        episodes = episodes[: int(cfg.max_episodes)]
        from wanderland_nav.envs.camera import camera_intrinsics
        from wanderland_nav.envs.config import CameraConfig

        cam = CameraConfig(**OmegaConf.to_container(cfg.camera, resolve=True))
        rollout = expert_rollout(episodes, scene.nav_from_scene, up_axis=scene.up_axis,
                                 camera=OmegaConf.to_container(cfg.camera, resolve=True),
                                 control_period=float(cfg.control_period), num_waypoints=int(cfg.num_waypoints),
                                 K=camera_intrinsics(cam).numpy(), stride=int(cfg.path_stride))
    elif episodes:
        used = set(rollout.episode_ids[rollout.episode_index.reshape(-1)].tolist())
        episodes = [e for e in episodes if str(e.episode_id) in used]

    mode = str(cfg.frames)
    if mode not in ("auto", "render", "none"):
        raise ValueError(f"frames={mode!r}: expected auto | render | none")
    frames = None
    if mode == "none":
        rollout.rgb = rollout.depth = None
    elif mode == "render" or rollout.rgb is None:
        rollout.rgb = None
        gaussians = _load_gaussians(scene, cfg.max_gaussians)
        if gaussians is None:
            print("replay: no 3dgs.ply for this scene; logging camera frustums without images")
        elif rollout.meta.camera:
            frames = render_rollout_frames(rollout.meta, gaussians, device=str(cfg.device))
    out = Path(cfg.out) if cfg.out is not None else src.with_suffix(".rrd")
    agents = list(cfg.agents) if cfg.agents is not None else None
    counts = write_recording(out, scene=scene, rollout=rollout, episodes=episodes, frames=frames, agents=agents,
                             max_points=int(cfg.max_points), max_cameras=int(cfg.max_cameras),
                             frame_chunk=int(cfg.frame_chunk))
    print(f"wrote {out} ({rollout.num_steps} steps x {rollout.num_agents} agents, {len(episodes)} episodes, "
          f"{time.perf_counter() - t0:.1f}s)")
    if cfg.viewer:
        open_viewer(out)
    return {**counts, "out": str(out)}


@hydra.main(version_base="1.3", config_path="../conf", config_name="replay")
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
