"""`replay`'s composition: a rollout file or an episodes file -> (rollout, scene, episodes, frame source)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from wanderland_nav.compose.schema import ReplayConfig
from wanderland_nav.envs.camera import camera_intrinsics
from wanderland_nav.evaluation.recording import expert_rollout, render_rollout_frames
from wanderland_nav.episodes import load_episodes
from wanderland_nav.render.lod import load_splat
from wanderland_nav.evaluation.rollouts import load_rollout
from wanderland_nav.scene import load_scene


def replay_inputs(c: ReplayConfig):
    """-> (rollout, scene or None, episodes it ran, source file). The scene: `scene_path`, else the
    rollout's recorded scene, else the episodes file's folder; episodes: the file the run used."""
    if c.rollout is None and c.episodes is None:
        raise ValueError("replay: give rollout=<file.npz> and/or episodes=<episodes.json>")
    rollout = load_rollout(c.rollout) if c.rollout is not None else None
    src = Path(c.rollout if c.rollout is not None else c.episodes)
    root = c.scene_path or (rollout.meta.scene_root if rollout is not None else None) or \
        (str(Path(c.episodes).parent) if c.episodes is not None else None)
    scene = None
    if root is not None:
        if not Path(root).is_dir():
            where = "scene_path" if c.scene_path else f"{src}: meta_json.scene_root"
            raise FileNotFoundError(f"{where}={root}: no such scene folder (pass scene_path=<folder>)")
        scene = load_scene(root)
    ep_path = c.episodes or (rollout.meta.episodes_path if rollout is not None else None)
    episodes = load_episodes(ep_path) if ep_path and Path(ep_path).is_file() else []
    if rollout is None:  # expert replay: the camera along the episodes' paths
        if scene is None:
            raise FileNotFoundError(f"episodes={c.episodes}: its scene folder is needed (scene_path=<folder>)")
        episodes = episodes[: c.max_episodes]
        rollout = expert_rollout(episodes, scene.nav_from_scene, up_axis=scene.up_axis,
                                 camera=dataclasses.asdict(c.camera), control_period=c.control_period,
                                 num_waypoints=c.num_waypoints, K=camera_intrinsics(c.camera).numpy(),
                                 stride=c.path_stride)
    elif episodes:
        used = set(rollout.episode_ids[rollout.episode_index.reshape(-1)].tolist())
        episodes = [e for e in episodes if str(e.episode_id) in used]
    return rollout, scene, episodes, src


def replay_frames(c: ReplayConfig, rollout, scene):
    """The frame source for steps without stored frames (None: none to show, with the reason printed)."""
    if c.frames not in ("auto", "render", "none"):
        raise ValueError(f"frames={c.frames!r}: expected auto | render | none")
    if c.frames == "none":
        rollout.rgb = rollout.depth = None
        return None
    if c.frames == "auto" and rollout.rgb is not None:
        return None
    rollout.rgb = None
    if not rollout.meta.camera or rollout.meta.camera.get("enabled", True) is False:
        print("replay: the run's camera was off; logging poses and camera frustums without images")
        return None
    if scene is None or scene.gaussians_path is None or not Path(scene.gaussians_path).is_file():
        print("replay: no 3dgs.ply for this scene; logging camera frustums without images")
        return None
    gaussians = load_splat(scene.gaussians_path, c.lod_px)
    return render_rollout_frames(rollout.meta, gaussians, device=c.device)
