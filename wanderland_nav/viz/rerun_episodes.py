"""Log navigation episodes to rerun: start (with heading), goal with its success radius, expert path.

Entities, one subtree per episode so the viewer can show/hide them one by one:
`world/episodes/ep_<id>/{start, heading, goal, goal_radius, reference_path, gt_locations}`,
all static, in the scene frame (episodes store scene-frame positions).
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from wanderland_nav.geometry import nav_from_scene_rotation


def entity_name(episode_id) -> str:
    """A path-safe entity name for an episode id."""
    return "ep_" + "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in str(episode_id))


def ground_circles(centers: np.ndarray, radii: np.ndarray, up_axis: str, n: int = 33) -> np.ndarray:
    """Circles `[E, n, 3]` (closed: first == last) of `radii [E]` around `centers [E, 3]` in the plane
    perpendicular to the scene's up axis (scene frame)."""
    R_sn = nav_from_scene_rotation(up_axis).T  # columns: nav x, y, z in the scene frame
    a = np.linspace(0.0, 2 * np.pi, n)
    ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1) @ R_sn.T  # [n, 3] unit ring, scene frame
    return centers[:, None, :] + radii[:, None, None] * ring[None]


def log_episodes(rec: rr.RecordingStream, episodes, up_axis: str, *, path: str = "world/episodes",
                 gt_locations: bool = False) -> int:
    """Log `episodes` (list of `wanderland_nav.episodes.Episode`); returns how many."""
    if not episodes:
        return 0
    starts = np.stack([np.asarray(e.start_position, np.float64) for e in episodes])  # [E, 3]
    goals = np.stack([np.asarray(e.goals[0].position, np.float64) for e in episodes])  # [E, 3]
    radii = np.asarray([float(e.goals[0].radius) for e in episodes])
    rings = ground_circles(goals, radii, up_axis)  # [E, n, 3]
    for i, e in enumerate(episodes):  # one entity subtree per episode (tens to hundreds), not a hot path
        base = f"{path}/{entity_name(e.episode_id)}"
        rec.log(f"{base}/start", rr.Points3D(starts[i:i + 1], colors=[[40, 200, 60]], radii=0.15,
                                             labels=[f"start {e.episode_id}"]), static=True)
        rec.log(f"{base}/goal", rr.Points3D(goals[i:i + 1], colors=[[230, 50, 50]], radii=0.15,
                                            labels=[f"goal {e.episode_id}"]), static=True)
        rec.log(f"{base}/goal_radius", rr.LineStrips3D([rings[i]], colors=[[230, 50, 50]], radii=0.02), static=True)
        ref = np.asarray(e.reference_path, np.float64)
        if len(ref) >= 2:
            rec.log(f"{base}/reference_path", rr.LineStrips3D([ref], colors=[[250, 200, 40]], radii=0.04),
                    static=True)
        if gt_locations and len(e.gt_locations):
            rec.log(f"{base}/gt_locations", rr.Points3D(np.asarray(e.gt_locations), colors=[[250, 200, 40]],
                                                        radii=0.03), static=True)
    return len(episodes)
