"""Start/goal sampling for expert episodes: near the capture cameras, on the navmesh, spread out.

Why near the cameras: a Wanderland scene is only photo-realistic (and its LiDAR geometry only
complete) along the capture trajectory, so episodes that wander far from it would be rendered
from holes in the splats. Everything here is batched over candidates: a round draws `batch_size`
start/goal pairs, snaps them in one navmesh call, checks islands and geodesic distances in one
call each, and only the greedy minimum-separation test walks the (few) survivors in order.

All positions passed in or out are in the SCENE frame; horizontal distances are measured in the
nav frame (`nav_from_scene @ p`, z up), so "within the camera radius" means on the ground plane.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import torch

from wanderland_nav.geometry import nav_from_scene_rotation

#: every reason a candidate pair can be thrown away, in the order the filters run
REJECTION_REASONS = (
    "off_mesh",          # the drawn ground point was not over the navmesh (snapping would put it on an edge)
    "not_near_camera",   # snapped start left the camera radius, fell to another floor or off the mesh
    "different_island",  # no goal candidate on the start's navmesh island
    "unreachable",       # same island by id, but the planner found no path
    "too_short",         # geodesic < min_geodesic
    "too_long",          # geodesic > max_geodesic
    "too_straight",      # geodesic / euclidean < min_ratio and not kept by straight_keep_prob
    "goal_in_reach",     # start already within the goal radius (euclidean)
    "too_close",         # start and goal both within min_separation of an accepted episode's
    "path_failed",       # find_path disagreed with the batched geodesic (unreachable or off by > tolerance)
)


@dataclass(frozen=True)
class SamplerSettings:
    """Where episodes may start and end. Distances in metres."""

    camera_radius: float = 3.0  # start/goal within this horizontal distance of a capture camera
    camera_max_drop: float = 3.0  # ... and at most this far below/above that camera (no other floors)
    min_geodesic: float = 3.0
    max_geodesic: float = 30.0
    min_ratio: float = 1.1  # geodesic/euclidean below this counts as "straight"; Habitat uses 1.1
    straight_keep_prob: float = 0.1  # fraction of straight pairs kept anyway (Habitat keeps 2 %)
    min_separation: float = 1.5  # an episode whose start AND goal are this close to another's is a duplicate
    goal_radius: float = 3.0  # success radius as Wanderland releases it ...
    goal_radius_fraction: float = 0.3  # ... but at most this fraction of the geodesic for short episodes
    min_goal_radius: float = 0.5
    path_tolerance: float = 0.05  # relative |find_path length - geodesic_distance| accepted (+ 0.1 m)
    batch_size: int = 256  # candidate pairs per round
    max_rounds: int = 200  # give up (and report) after this many rounds
    # share of rounds whose starts and goals are all drawn around cameras inside an indoor region (the scene's
    # `indoor_regions`): routes inside buildings, which pairs drawn over a whole district would rarely give
    indoor_fraction: float = 0.0

    def __post_init__(self):
        checks = {
            "camera_radius": self.camera_radius > 0, "camera_max_drop": self.camera_max_drop > 0,
            "min_geodesic": self.min_geodesic >= 0, "max_geodesic": self.max_geodesic > self.min_geodesic,
            "min_ratio": self.min_ratio >= 1.0, "straight_keep_prob": 0.0 <= self.straight_keep_prob <= 1.0,
            "min_separation": self.min_separation >= 0, "goal_radius": self.goal_radius > 0,
            "goal_radius_fraction": self.goal_radius_fraction > 0,
            "min_goal_radius": 0 < self.min_goal_radius <= self.goal_radius,
            "path_tolerance": self.path_tolerance >= 0, "batch_size": self.batch_size > 0, "max_rounds": self.max_rounds > 0,
            "indoor_fraction": 0.0 <= self.indoor_fraction <= 1.0,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"SamplerSettings: invalid value for {bad[0]}={getattr(self, bad[0])!r}")

    def goal_radius_for(self, geodesic: np.ndarray) -> np.ndarray:
        """`[K]` success radius: `goal_radius`, shrunk for short episodes, never below the minimum."""
        return np.clip(self.goal_radius_fraction * np.asarray(geodesic), self.min_goal_radius, self.goal_radius)


@dataclass
class SampledPairs:
    """Accepted start/goal pairs, in acceptance order. Scene frame."""

    starts: np.ndarray  # [E, 3] float64
    goals: np.ndarray  # [E, 3] float64
    paths: list[np.ndarray]  # E x [P_e, 3] shortest-path corners from NavMesh.find_path
    geodesic: np.ndarray  # [E] length of each path (metres)
    euclidean: np.ndarray  # [E]
    island: np.ndarray  # [E] int
    goal_radius: np.ndarray  # [E]
    rejections: Counter
    candidates: int  # pairs drawn in total
    rounds: int


class EndpointSampler:
    """Draws start/goal pairs near capture cameras on one navmesh (see module docstring)."""

    def __init__(self, navmesh, camera_centers: np.ndarray, nav_from_scene: np.ndarray, settings: SamplerSettings,
                 camera_indoor: np.ndarray | None = None):
        self.navmesh = navmesh
        self.s = settings
        self.R_ns = np.asarray(nav_from_scene, dtype=np.float64)  # [3, 3]
        nm_up = getattr(getattr(navmesh, "settings", None), "up_axis", None)
        if nm_up is not None and not np.allclose(nav_from_scene_rotation(nm_up), self.R_ns):
            raise ValueError(f"EndpointSampler: the navmesh was baked with up axis {nm_up} but the scene's frame "
                             "differs (nav_from_scene); re-run prepare for this scene's up axis")
        cams = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3)  # [M, 3] scene frame
        if len(cams) == 0:
            raise ValueError("EndpointSampler: the scene has no capture positions to sample around (no cameras, "
                             "no lidar/poses.txt): episodes start near the capture trajectory")
        self.cams_nav = cams @ self.R_ns.T  # [M, 3] nav frame
        # ground height under every camera: the navmesh point closest to the camera centre. Cameras
        # whose nearest ground is not below them within camera_max_drop (e.g. above a hole) are unusable.
        ground = self._to_nav(self._snap(cams))  # [M, 3]
        drop = self.cams_nav[:, 2] - ground[:, 2]
        horiz = np.linalg.norm(ground[:, :2] - self.cams_nav[:, :2], axis=-1)
        ok = (drop >= -0.5) & (drop <= self.s.camera_max_drop) & (horiz <= self.s.camera_radius)
        if not ok.any():
            raise ValueError(
                f"EndpointSampler: no capture camera has navigable ground within {self.s.camera_radius} m "
                f"horizontally and {self.s.camera_max_drop} m below it; is the up axis right?")
        self.usable = np.flatnonzero(ok)  # [M'] camera indices used as sampling centres
        indoor = np.zeros(len(cams), bool) if camera_indoor is None else np.asarray(camera_indoor, bool).reshape(-1)
        self.usable_indoor = self.usable[indoor[self.usable]]  # the centres of indoor rounds
        self.ground_nav = ground  # [M, 3]
        self.camera_heights = drop[ok]  # [M'] camera height above the navmesh (for goal images)

    # ----------------------------------------------------------------- helpers

    def _to_nav(self, p_scene: np.ndarray) -> np.ndarray:
        return p_scene @ self.R_ns.T

    def _to_scene(self, p_nav: np.ndarray) -> np.ndarray:
        return p_nav @ self.R_ns

    def _snap(self, p_scene: np.ndarray) -> np.ndarray:
        # no snap limit here (the planner's default is ~1 m): how far a point moved is judged by
        # near_camera() afterwards, per point, instead of one far point failing the whole batch
        return np.asarray(self.navmesh.snap_point(np.asarray(p_scene, dtype=np.float64), max_distance=1e9),
                          dtype=np.float64)

    def near_camera(self, p_scene: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """`bool [N]`: within `camera_radius` (ground plane) of a camera that is at most
        `camera_max_drop` above/below. Brute force in chunks: [chunk, M] distances."""
        p = self._to_nav(np.asarray(p_scene, dtype=np.float64).reshape(-1, 3))
        out = np.zeros(len(p), dtype=bool)
        r2 = self.s.camera_radius ** 2
        for i in range(0, len(p), chunk):
            q = p[i:i + chunk]
            d2 = ((q[:, None, :2] - self.cams_nav[None, :, :2]) ** 2).sum(-1)  # [c, M]
            dz = np.abs(self.cams_nav[None, :, 2] - q[:, None, 2])
            out[i:i + chunk] = ((d2 <= r2) & (dz <= self.s.camera_max_drop)).any(-1)
        return out

    def draw_points(self, n: int, rng: np.random.Generator, centres: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Points drawn uniformly in discs around random usable cameras (of `centres`, default all usable ones),
        put on the navmesh.

        Returns `[n, 3]` scene-frame snapped points and `bool [n]` "on mesh": the drawn ground
        point was over the navmesh (snapping moved it < 5 cm sideways) and the planner calls the
        snapped point navigable. Off-mesh draws are rejected rather than kept on the navmesh edge,
        so starts and goals are uniform over the walkable area and never pressed against a wall.
        """
        centres = self.usable if centres is None else centres
        cam = centres[rng.integers(len(centres), size=n)]
        rad = self.s.camera_radius * np.sqrt(rng.random(n))
        ang = rng.random(n) * 2 * np.pi
        p = self.ground_nav[cam].copy()
        p[:, 0] = self.cams_nav[cam, 0] + rad * np.cos(ang)
        p[:, 1] = self.cams_nav[cam, 1] + rad * np.sin(ang)
        raw = self._to_scene(p)
        # cheap point location first (within 1.5 m of the camera's ground level, so the right floor);
        # only those draws are snapped (the exhaustive closest-point search is for off-mesh points)
        over = np.asarray(self.navmesh.is_navigable(raw, max_height_delta=1.5), dtype=bool).reshape(-1)
        snapped = raw.copy()
        on = np.zeros(n, dtype=bool)
        if over.any():
            snapped[over] = self._snap(raw[over])
            moved = np.linalg.norm(self._to_nav(snapped[over])[:, :2] - p[over, :2], axis=-1)
            on[over] = (moved < 0.05) & np.asarray(self.navmesh.is_navigable(snapped[over]), dtype=bool).reshape(-1)
        return snapped, on

    # ----------------------------------------------------------------- main loop

    def _round(self, K: int, rng: np.random.Generator, rej: Counter, centres: np.ndarray | None = None):
        """One round of `K` candidate pairs (drawn around `centres`, default every usable camera) through every
        batched filter (rejections counted in `rej`).

        -> None when none survives, else (starts `[K, 3]`, goals `[K, 3]`, start islands `[K]`,
        euclidean `[K]`, geodesic `[K]`, goal radius `[K]`, surviving indices `[n]`)."""
        s = self.s
        pts, on = self.draw_points(2 * K, rng, centres)  # [2K, 3], [2K]
        keep_u = rng.random(K)  # drawn every round so the stream does not depend on filters
        pick_u = rng.random(K)
        near = self.near_camera(pts) & on
        isl = np.full(2 * K, -1, dtype=np.int64)  # [2K]; off-mesh draws never reach the planner
        if on.any():
            isl[on] = np.asarray(self.navmesh.island_of(pts[on], max_distance=0.05)).astype(np.int64)
        st, isl_s, m = pts[:K], isl[:K], near[:K] & (isl[:K] >= 0)
        rej["off_mesh"] += int((~on[:K]).sum())
        # pair every start with a random goal from the second half ON ITS ISLAND (scenes split into
        # many islands would otherwise waste most pairs): goals grouped by island, index by pick_u
        g_ok = near[K:] & (isl[K:] >= 0)
        g_idx = K + np.flatnonzero(g_ok)
        order = np.argsort(isl[g_idx], kind="stable")
        g_idx, g_isl = g_idx[order], isl[g_idx][order]
        lo = np.searchsorted(g_isl, isl_s, side="left")
        cnt = np.searchsorted(g_isl, isl_s, side="right") - lo
        rej["not_near_camera"] += int((~m & on[:K]).sum())
        has_goal = m & (cnt > 0)
        rej["different_island"] += int((m & ~has_goal).sum())
        m = has_goal
        choice = g_idx[np.clip(lo + np.floor(pick_u * cnt).astype(np.int64), 0, max(len(g_idx) - 1, 0))] \
            if len(g_idx) else np.zeros(K, dtype=np.int64)
        go = pts[np.where(m, choice, K)]  # [K, 3]; rows with m False are ignored below
        idx = np.flatnonzero(m)
        if idx.size == 0:
            return None
        # geodesic >= euclidean: pairs already too far apart in a straight line skip the planner
        euc = np.linalg.norm(go - st, axis=-1)
        far = m & (euc > s.max_geodesic)
        rej["too_long"] += int(far.sum())
        m &= ~far
        idx = np.flatnonzero(m)
        geo = np.full(K, np.inf)
        if idx.size:
            geo[idx] = torch.as_tensor(
                self.navmesh.geodesic_distance(st[idx], go[idx])).double().cpu().numpy()
        fin = np.isfinite(geo)
        rej["unreachable"] += int((m & ~fin).sum())
        m &= fin
        short = m & (geo < s.min_geodesic)
        rej["too_short"] += int(short.sum())
        m &= ~short
        long_ = m & (geo > s.max_geodesic)
        rej["too_long"] += int(long_.sum())
        m &= ~long_
        ratio = geo / np.maximum(euc, 1e-6)
        straight = m & (ratio < s.min_ratio) & (keep_u >= s.straight_keep_prob)
        rej["too_straight"] += int(straight.sum())
        m &= ~straight
        radius = s.goal_radius_for(np.where(np.isfinite(geo), geo, 0.0))
        reach = m & (euc <= radius)
        rej["goal_in_reach"] += int(reach.sum())
        m &= ~reach
        cand = np.flatnonzero(m)
        if cand.size == 0:
            return None
        return st, go, isl_s, euc, geo, radius, cand

    def sample(self, num: int, rng: np.random.Generator, progress=None) -> SampledPairs:
        """Accept up to `num` pairs; stops early after `max_rounds` rounds (see `rejections`)."""
        s = self.s
        rej: Counter = Counter({r: 0 for r in REJECTION_REASONS})
        acc_s, acc_g, acc_geo, acc_euc, acc_isl, acc_rad, acc_path = [], [], [], [], [], [], []
        acc_s_nav = np.zeros((0, 3))
        acc_g_nav = np.zeros((0, 3))
        drawn = rounds = 0

        def accept(survivors) -> None:
            """Minimum separation and the expert path for one round's survivors, in draw order."""
            nonlocal acc_s_nav, acc_g_nav
            if survivors is None:
                return
            st, go, isl_s, euc, geo, radius, cand = survivors
            # minimum separation: against everything accepted so far (vectorised), then greedily
            # inside this round's survivors (few), in draw order so the result is deterministic.
            st_nav, go_nav = self._to_nav(st[cand]), self._to_nav(go[cand])
            for j, c in enumerate(cand):
                if len(acc_s) >= num:
                    break
                if len(acc_s_nav):
                    d = np.maximum(np.linalg.norm(acc_s_nav - st_nav[j], axis=-1),
                                   np.linalg.norm(acc_g_nav - go_nav[j], axis=-1))
                    # the same route walked backwards is a duplicate too
                    d_rev = np.maximum(np.linalg.norm(acc_g_nav - st_nav[j], axis=-1),
                                       np.linalg.norm(acc_s_nav - go_nav[j], axis=-1))
                    if min(d.min(), d_rev.min()) < s.min_separation:
                        rej["too_close"] += 1
                        continue
                # the expert path itself (one planner query per accepted episode, not per candidate)
                res = self.navmesh.find_path(st[c], go[c])
                pts, length = res[0], res[1]
                reachable = bool(getattr(res, "reachable", np.isfinite(length)))
                if (not reachable or pts is None or len(pts) < 2
                        or abs(float(length) - geo[c]) > s.path_tolerance * geo[c] + 0.1):
                    rej["path_failed"] += 1
                    continue
                acc_path.append(np.asarray(pts, dtype=np.float64).reshape(-1, 3))
                acc_s.append(st[c]); acc_g.append(go[c]); acc_geo.append(float(length)); acc_euc.append(euc[c])
                acc_isl.append(isl_s[c]); acc_rad.append(radius[c])
                acc_s_nav = np.vstack([acc_s_nav, st_nav[j]])
                acc_g_nav = np.vstack([acc_g_nav, go_nav[j]])
                if progress is not None:
                    progress(1)

        while len(acc_s) < num and rounds < s.max_rounds:
            rounds += 1
            # a round costs one batched planner call over its pairs: draw fewer near the end
            K = min(s.batch_size, max(32, 16 * (num - len(acc_s))))
            drawn += K
            # `indoor_fraction` of the pairs drawn around indoor cameras only (none: the stream is as without it)
            K_in = int(round(s.indoor_fraction * K)) if len(self.usable_indoor) else 0
            for k, centres in ((K_in, self.usable_indoor), (K - K_in, None)):
                if k > 0 and len(acc_s) < num:
                    accept(self._round(k, rng, rej, centres))
        E = len(acc_s)
        return SampledPairs(
            starts=np.asarray(acc_s, dtype=np.float64).reshape(E, 3),
            goals=np.asarray(acc_g, dtype=np.float64).reshape(E, 3),
            paths=acc_path,
            geodesic=np.asarray(acc_geo, dtype=np.float64),
            euclidean=np.asarray(acc_euc, dtype=np.float64),
            island=np.asarray(acc_isl, dtype=np.int64),
            goal_radius=np.asarray(acc_rad, dtype=np.float64),
            rejections=rej,
            candidates=drawn,
            rounds=rounds,
        )
