"""Same routes in both worlds: the grounded test episodes mapped into a degraded environment's frame.

The paper's Fig.-8 protocol evaluates the SAME routes in the grounded and in the degraded simulator.
Each environment's own episodes (sampled on its own navmesh) measure something else: a fragmented
navmesh only offers short episodes, so a degraded world can look easier than the grounded one.

A degraded build records its pose error as one field (`degrade.PoseCorrection`, `degradation.npz`):
scale presets scale about the origin by the known factor, `drift` moves every point with the known
pose error of its nearest capture camera, and the mesh presets (`splat_mesh`, `holes`) keep the frame
(identity field). Each grounded episode's start, goal and route corners go through that field; the
episode is kept only when its mapped start and goal snap onto the degraded navmesh (within its snap
distance) and the goal is reachable from the start there. Every dropped route is counted by reason;
none is replaced. A kept episode gets the degraded navmesh's own shortest path (its `geodesic_distance`,
`reference_path` and dense `gt_locations`, which the env's SPL and route input read), the start heading
of the mapped grounded route, the grounded success radius (the simulator's rule in its own metres) and
the same split and id; goal views of the grounded world are dropped (no degraded view exists for them).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planners import NavMesh
from wanderland_nav.degrade.build import CORRECTION
from wanderland_nav.degrade.poses import PoseCorrection
from wanderland_nav.episodes.paths import first_heading_nav, polyline_length, resample_polyline
from wanderland_nav.episodes.schema import Episode, Goal, load_episodes, rotation_from_yaw, save_episodes

#: why a grounded route is not evaluated in a degraded world (counted, in this order of checks)
DROP_REASONS = ("start off the navmesh", "goal off the navmesh", "goal unreachable")


@dataclass
class MappedRoutes:
    """The mapped episodes (degraded scene frame) and what happened to each grounded route."""

    episodes: list  # list[Episode]
    asked: int
    dropped: dict[str, int] = field(default_factory=dict)  # reason -> count
    dropped_ids: list = field(default_factory=list)  # grounded episode ids not evaluated

    @property
    def kept(self) -> int:
        return len(self.episodes)

    def as_dict(self) -> dict:
        return {"asked": self.asked, "kept": self.kept, "dropped": dict(self.dropped),
                "dropped_ids": list(self.dropped_ids)}


def _route_start_yaw(corners_scene: np.ndarray, R_ns: np.ndarray) -> float:
    """Nav-frame heading of the first segment of a mapped route `[K,3]` (scene frame)."""
    return float(first_heading_nav(np.asarray(corners_scene, dtype=np.float64) @ R_ns.T))


def _mapped_episode(ep, path_points: np.ndarray, mapped_corners: np.ndarray, navmesh, R_ns: np.ndarray,
                    up_axis: str, step_size: float):
    """One grounded `Episode` rebuilt on the degraded navmesh's shortest path `path_points [P,3]`."""
    dense = resample_polyline(path_points @ R_ns.T, step_size, horizontal=True) @ R_ns  # [L,3] scene frame
    dense = np.asarray(navmesh.snap_point(dense, max_distance=1e9), dtype=np.float64)
    extras = {k: v for k, v in ep.extras.items() if k not in ("goal_image", "island", "point_goal_polar")}
    extras.update({"grounded_episode_id": ep.episode_id, "up_axis": up_axis,
                   "euclidean_distance": float(np.linalg.norm(path_points[-1] - path_points[0]))})
    q = rotation_from_yaw(np.asarray(_route_start_yaw(mapped_corners, R_ns)), up_axis).reshape(4)
    out = Episode(episode_id=ep.episode_id, scene_id=ep.scene_id, start_position=path_points[0],
                  start_rotation_wxyz=q, geodesic_distance=float(polyline_length(path_points)),
                  goals=[Goal(position=path_points[-1], radius=ep.goal_radius)], instruction_text=ep.instruction_text,
                  reference_path=path_points, gt_locations=dense, gt_steps=int(len(dense) - 1), extras=extras)
    out.validate(where=f"grounded episode {ep.episode_id} mapped")
    return out


def map_routes(episodes, correction, navmesh, nav_from_scene: np.ndarray, up_axis: str, *,
               step_size: float = 0.25) -> MappedRoutes:
    """Grounded `episodes` (scene frame) -> `MappedRoutes` in the degraded world of `correction`
    (a `degrade.PoseCorrection`) walking on `navmesh` (the degraded `planners.NavMesh`)."""
    R_ns = np.asarray(nav_from_scene, dtype=np.float64)
    E = len(episodes)
    starts = correction.apply_points(np.asarray([e.start_position for e in episodes]).reshape(E, 3))
    goals = correction.apply_points(np.asarray([e.goal_position for e in episodes]).reshape(E, 3))
    empty = len(navmesh.tris) == 0
    s_isl = np.full(E, -1) if empty else navmesh.island_of(starts)  # [E], -1: beyond the snap distance
    g_isl = np.full(E, -1) if empty else navmesh.island_of(goals)
    reason = np.where(s_isl < 0, 0, np.where(g_isl < 0, 1, np.where(s_isl != g_isl, 2, -1)))  # index in DROP_REASONS
    kept = []
    for i in np.flatnonzero(reason < 0):  # one exact shortest path per surviving route (setup, not a hot path)
        res = navmesh.find_path(starts[i], goals[i])
        if not res.reachable:
            reason[i] = 2
            continue
        corners = correction.apply_points(np.asarray(episodes[i].reference_path, dtype=np.float64))
        kept.append(_mapped_episode(episodes[i], np.asarray(res.points, dtype=np.float64), corners, navmesh, R_ns,
                                    up_axis, step_size))
    dropped = {r: int((reason == k).sum()) for k, r in enumerate(DROP_REASONS)}
    return MappedRoutes(kept, E, dropped, [episodes[i].episode_id for i in np.flatnonzero(reason >= 0)])


def grounded_routes_file(grounded_episodes: Path, split: str, num: int | None, degraded_scene, out_dir: Path
                         ) -> tuple[Path, MappedRoutes | dict]:
    """The first `num` grounded `split` episodes mapped into `degraded_scene` (prepared), written once to
    `out_dir/routes_<env>_<hash8>.json` (atomic; the hash covers the grounded file, split, num and the
    degraded navmesh) -> (path, counts); `counts["kept"]` may be 0 (every route infeasible there)."""
    root = Path(degraded_scene.root)
    key = hashlib.sha256(json.dumps([hashlib.sha256(Path(grounded_episodes).read_bytes()).hexdigest(), split, num,
                                     hashlib.sha256(Path(degraded_scene.navmesh_path).read_bytes()).hexdigest()])
                         .encode()).hexdigest()[:8]
    path = Path(out_dir) / f"routes_{root.name}_{key}.json"
    if path.is_file():
        return path, json.loads(path.read_text())["mapped_from"]
    eps = load_episodes(grounded_episodes, split=split)
    eps = eps if num is None else eps[:num]
    corr_path = root / CORRECTION
    if not corr_path.is_file():
        raise FileNotFoundError(f"{root}: no {CORRECTION}; grounded routes can only be mapped into a degraded build")
    mapped = map_routes(eps, PoseCorrection.load(corr_path), NavMesh.load(degraded_scene.navmesh_path),
                        degraded_scene.nav_from_scene, degraded_scene.up_axis)
    info = {"grounded_episodes": str(grounded_episodes), "split": split, **mapped.as_dict()}
    path.parent.mkdir(parents=True, exist_ok=True)
    save_episodes(path, mapped.episodes, extras={"mapped_from": info})  # may hold no episode: counted, not hidden
    return path, info
