"""Expert waypoints along a path, and the reference policies built on them: the path-following expert and random.

`waypoints_along_path` is the one definition of "what a perfect waypoint policy outputs" (K points
ahead along a path, in the body frame): `ExpertPolicy` below, the BC labels (`rl.bc.ExpertPaths`) and
the expert replay (`envs.recording.expert_rollout`, via `waypoints_along_samples`) all call it.

The expert is privileged: it reads `AGENT_POSITION`, `AGENT_YAW`, `EPISODE_INDEX` and
`STEP_COUNT` and follows each episode's expert path (the navmesh shortest path stored as
`reference_path`, or a fresh `NavMesh.find_path` from the start), emitting what a learned policy
emits: K body-frame waypoints spaced one control period of travel apart (or the `(v, omega)` that
tracks the first of them). It is the upper bound in the evaluation table and the sanity check of the
whole stack (frames, kinematics, navmesh motion, distances, metrics): if it does not reach SR ~1
something in that chain is wrong.

All per-agent work is batched over padded paths `[E, P, 3]`: projection onto the path, arc-length
progress and waypoint interpolation are tensor ops; loops only run over episodes at construction.
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from wanderland_nav import keys
from wanderland_nav.envs.kinematics import track_point_command
from wanderland_nav.geometry import world_to_body_2d

PATH_SOURCES = ("reference", "navmesh")


def pad_paths(paths, where: str = "paths", dim: int = 3) -> np.ndarray:
    """E polylines `[P_i, dim]` -> one array `[E, P, dim]` (float64), each padded by repeating its last point.

    The padding adds zero-length segments, so arc lengths and interpolation along a padded path are
    those of the original. Raises naming `where` and the episode for an empty or ragged path.
    """
    if not len(paths):
        raise ValueError(f"{where}: no episodes")
    arrs = [np.asarray(p, np.float64) for p in paths]
    for i, p in enumerate(arrs):
        if p.ndim != 2 or p.shape[1] != dim or len(p) < 1:
            raise ValueError(f"{where}: episode {i} path must be [L>=1, {dim}], got {p.shape}")
    P = max(len(p) for p in arrs)
    return np.stack([np.concatenate([p, np.repeat(p[-1:], P - len(p), 0)]) for p in arrs])


def arc_lengths(path: torch.Tensor) -> torch.Tensor:
    """Cumulative arc length `[..., P]` (0 at the first point) of polylines `[..., P, D]`."""
    seg = (path[..., 1:, :] - path[..., :-1, :]).norm(dim=-1)
    return torch.cat([torch.zeros_like(seg[..., :1]), seg.cumsum(-1)], dim=-1)


def waypoints_along_path(path: torch.Tensor, cum: torch.Tensor, start: torch.Tensor, agent_xy: torch.Tensor,
                         agent_yaw: torch.Tensor, num_waypoints: int, spacing: float) -> torch.Tensor:
    """The expert's K waypoints: path points at arc lengths `start + spacing * (1..K)` (clamped to the
    path's end), in the agent's body frame (x forward, y left), `[N, K, 2]` metres.

    path `[N, P, D]` (nav frame, D = 2 or 3, padded as `pad_paths`), cum `[N, P]` its `arc_lengths`,
    start `[N]` the arc length the agent has reached, agent_xy `[N, 2]`, agent_yaw `[N]`. This is the
    one definition of "what a perfect waypoint policy outputs": the BC labels, the evaluation expert
    and the expert replay all call it, each with its own notion of where the agent is on the path.
    """
    steps = torch.arange(1, num_waypoints + 1, device=path.device, dtype=cum.dtype) * spacing
    target = torch.minimum(start[:, None].to(cum.dtype) + steps, cum[:, -1:])  # [N, K]
    hi = torch.searchsorted(cum.contiguous(), target.contiguous(), right=False).clamp(1, cum.shape[1] - 1)
    lo = hi - 1
    c_lo, c_hi = cum.gather(1, lo), cum.gather(1, hi)
    w = ((target - c_lo) / (c_hi - c_lo).clamp_min(1e-6)).clamp(0, 1)[..., None]  # [N, K, 1]
    dim = path.shape[-1]
    p_lo = path.gather(1, lo[..., None].expand(-1, -1, dim))
    p_hi = path.gather(1, hi[..., None].expand(-1, -1, dim))
    pts = p_lo * (1 - w) + p_hi * w  # [N, K, D]
    return world_to_body_2d(pts[..., :2], agent_xy[:, :2].to(pts.dtype), agent_yaw.reshape(-1).to(pts.dtype))


def waypoints_along_samples(path: np.ndarray, yaw: np.ndarray, num_waypoints: int) -> np.ndarray:
    """Body-frame waypoints `[L, K, 2]` for an agent at each of the first L samples of `path [L+1, D]`
    (nav frame) with headings `yaw [L]`: `waypoints_along_path` spaced by the path's mean sample
    spacing, i.e. the next K samples of a uniformly resampled path (an expert replay's "prediction")."""
    p = torch.as_tensor(np.asarray(path, np.float64))
    cum = arc_lengths(p)  # [L+1]
    L = len(yaw)
    wp = waypoints_along_path(p.expand(L, -1, -1), cum.expand(L, -1), cum[:L], p[:L, :2],
                              torch.as_tensor(np.asarray(yaw, np.float64)), num_waypoints, float(cum[-1]) / L)
    return wp.numpy()


class ExpertPolicy(TensorDictModuleBase):
    """Follows each episode's shortest path; waypoint or velocity actions to match `env.action_spec`.

    Args:
        env: the `NavEnv` (for its episodes, frame, navmesh and kinematics config).
        source: "reference" uses the episode's `reference_path` (falls back to the navmesh when a
            path is missing); "navmesh" recomputes `find_path(start, goal)`.
        spacing: metres between waypoints; default one control period at full speed.
        window: metres of path ahead of the current progress searched when projecting the agent,
            so a path that doubles back near itself cannot make the expert skip ahead or back.
    """

    def __init__(self, env, source: str = "reference", spacing: float | None = None, window: float = 3.0):
        super().__init__()
        if source not in PATH_SOURCES:
            raise ValueError(f"ExpertPolicy.source: expected one of {PATH_SOURCES}, got {source!r}")
        k = env.config.kinematics
        self.kin = k
        self.mode = k.action_mode
        self.num_waypoints = k.num_waypoints
        self.spacing = float(spacing) if spacing is not None else k.max_linear_speed * k.control_period
        self.window = float(window)
        self.in_keys = [keys.AGENT_POSITION, keys.AGENT_YAW, keys.EPISODE_INDEX, keys.STEP_COUNT]
        self.out_keys = [keys.ACTION]
        paths = [self._episode_path(env, i, source) for i in range(len(env.episodes))]  # nav frame [P_i, 3]
        padded = torch.as_tensor(pad_paths(paths, "ExpertPolicy"))  # [E, P, 3] float64
        self.register_buffer("paths", padded.to(env.device, torch.float32), persistent=False)
        self.register_buffer("cum", arc_lengths(padded).to(env.device, torch.float32), persistent=False)  # [E, P]
        # [B] arc length reached along each agent's path: a buffer, so `to(device)` moves it with the paths
        self.register_buffer("_progress", None, persistent=False)
        self.crowd = getattr(env, "crowd", None)  # pedestrians: the expert waits while one is in its way

    @staticmethod
    def _episode_path(env, i: int, source: str) -> np.ndarray:
        e = env.episodes[i]
        start = env.table.start_position[i].double().cpu().numpy()
        goal = env.table.goal_position[i].double().cpu().numpy()
        R = np.asarray(env.scene.nav_from_scene, dtype=np.float64)
        ref = np.asarray(getattr(e, "reference_path", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
        if source == "navmesh" or len(ref) < 2:
            res = env.navmesh.find_path(np.asarray(e.start_position, dtype=np.float64), np.asarray(e.goal_position, dtype=np.float64))
            pts, _ = res
            ref = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
            if len(ref) == 0:
                raise ValueError(f"ExpertPolicy: episodes[{i}] (id {e.episode_id}): no navmesh path from start to goal")
        p = ref @ R.T
        p = np.concatenate([start[None], p[1:] if np.linalg.norm(p[0] - start) < 1.0 else p, goal[None]])
        keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=-1) > 1e-6])
        return ExpertPolicy._ease_corners(env, p[keep])

    @staticmethod
    def _ease_corners(env, p: np.ndarray, offsets=(0.3, 0.2, 0.1)) -> np.ndarray:
        """Move each interior corner of a shortest path `[P, 3]` (nav) away from the obstacle it wraps.

        Why: a navmesh shortest path touches the walkable boundary at every corner, so a body that
        drifts a few centimetres to the wrong side of a corner meets the wall and cannot enter a
        narrow passage. The obstacle lies inside the turn; the corner moves by the largest of
        `offsets` (metres) along the outward bisector that stays on the navmesh and keeps both of its
        segments walkable. Without the segment test a corner eased away from one obstacle could send
        the path through another (demo episode 68: a wall wedge 0.14 m beside the route; the expert
        then pushed into the wedge until `stuck_steps`). Corners whose segments stay blocked step down
        to smaller offsets, and to the planner's own corner (offset 0) last.
        """
        if len(p) < 3:
            return p
        d = np.diff(p[:, :2], axis=0)
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
        out = d[:-1] - d[1:]  # [P-2, 2] points away from the inside of each turn
        n = np.linalg.norm(out, axis=-1, keepdims=True)
        out = np.where(n > 1e-3, out / np.maximum(n, 1e-9), 0.0)
        levels = np.asarray([*offsets, 0.0])  # [O+1] metres, the last one the planner's corner
        cand = p[1:-1, None, :].repeat(len(levels), 1).copy()  # [P-2, O+1, 3]
        cand[..., :2] += out[:, None, :] * levels[None, :, None]
        ok = env._navigable(torch.as_tensor(cand.reshape(-1, 3), dtype=torch.float32)).cpu().numpy()
        ok = ok.reshape(len(p) - 2, len(levels))
        ok[:, -1] = True
        level = ok.argmax(1)  # [P-2] largest navigable offset per corner
        rows = np.arange(len(p) - 2)
        for _ in range(len(levels)):  # step blocked corners down; each round moves some corner one level
            q = p.copy()
            q[1:-1] = cand[rows, level]
            clear = ExpertPolicy._walkable(env, q[:-1], q[1:])  # [P-1] segments
            bad = ~(clear[:-1] & clear[1:]) & (level < len(levels) - 1)  # corners beside a blocked segment
            if not bad.any():
                break
            for r in np.flatnonzero(bad):  # next navigable level (a few corners, a few levels)
                level[r] = level[r] + 1 + ok[r, level[r] + 1:].argmax()
        q = p.copy()
        q[1:-1] = cand[rows, level]
        return q

    @staticmethod
    def _walkable(env, a: np.ndarray, b: np.ndarray, tol: float = 0.02) -> np.ndarray:
        """`[S]` whether the motion model walks each straight segment a[S,3] -> b[S,3] (nav) to within `tol`
        metres of its end (a slide along a wall it merely grazes still counts)."""
        end, _ = env._move(torch.as_tensor(a, dtype=torch.float32), torch.as_tensor(b, dtype=torch.float32))
        return (np.linalg.norm(end.cpu().numpy()[:, :2] - b[:, :2], axis=-1) <= tol)

    def reset(self) -> None:
        self._progress = None

    @torch.no_grad()
    def forward(self, td: TensorDictBase) -> TensorDictBase:
        missing = [k for k in self.in_keys if td.get(k, None) is None]
        if missing:
            raise KeyError(f"ExpertPolicy reads the privileged ground truth {missing}, which this tensordict lacks: "
                           "a policy-facing env (wanderland_nav.make_env) leaves it out. Build the env with "
                           "env={'privileged': True} for these keys, or with env={'expert_action': True} and act on "
                           "td['expert_action'], the expert's action computed inside the env")
        pos = td.get(keys.AGENT_POSITION).float()  # [B, 3] nav
        yaw = td.get(keys.AGENT_YAW).float().reshape(-1)  # [B]
        ep = td.get(keys.EPISODE_INDEX).reshape(-1).long()
        fresh = td.get(keys.STEP_COUNT).reshape(-1) == 0
        s_prev = self._progress
        if s_prev is None or s_prev.shape != yaw.shape:
            s_prev = torch.zeros_like(yaw)
        s_prev = torch.where(fresh, torch.zeros_like(s_prev), s_prev)
        s = self._project(pos, ep, s_prev)
        self._progress = s
        wp = waypoints_along_path(self.paths[ep], self.cum[ep], s, pos, yaw, self.num_waypoints, self.spacing)
        if self.crowd is not None and self.crowd.B == wp.shape[0]:  # yield: stand still this step
            wait = self.crowd.in_the_way(pos, yaw, wp).to(wp.device)
            wp = torch.where(wait[:, None, None], torch.zeros_like(wp), wp)
        if self.mode == "velocity":
            v, omega = track_point_command(wp[:, 0], self.kin.control_period, self.kin.control_period, self.kin)
            if self.crowd is not None and self.crowd.B == wp.shape[0]:
                v, omega = torch.where(wait, torch.zeros_like(v), v), torch.where(wait, torch.zeros_like(omega), omega)
            action = torch.stack([v, omega], -1)
        else:
            action = wp
        td.set(keys.ACTION, action.to(td.device) if td.device is not None else action)
        return td

    def _project(self, pos: torch.Tensor, ep: torch.Tensor, s_prev: torch.Tensor) -> torch.Tensor:
        """Arc length `[B]` of the closest path point within [s_prev - 0.5, s_prev + window]; never decreases."""
        path, cum = self.paths[ep], self.cum[ep]  # [B, P, 3], [B, P]
        a, ab = path[:, :-1], path[:, 1:] - path[:, :-1]  # [B, S, 3]
        seg = cum[:, 1:] - cum[:, :-1]  # [B, S]
        t = (((pos[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp_min(1e-12)).clamp(0.0, 1.0)
        q = a + t[..., None] * ab
        d = (pos[:, None] - q).norm(dim=-1)  # [B, S]
        arc = cum[:, :-1] + t * seg
        ok = (arc >= s_prev[:, None] - 0.5) & (arc <= s_prev[:, None] + self.window)
        d = torch.where(ok, d, torch.full_like(d, float("inf")))
        best = d.argmin(-1)
        s_best = arc.gather(-1, best[:, None]).squeeze(-1)
        s_best = torch.where(ok.any(-1), s_best, s_prev)
        return torch.maximum(s_prev, s_best)

class RandomPolicy(TensorDictModuleBase):
    """Uniform actions within `action_spec`'s bounds from its own seeded generator (the lower bound)."""

    def __init__(self, action_spec, seed: int = 0):
        super().__init__()
        self.in_keys = []
        self.out_keys = [keys.ACTION]
        self.low = action_spec.space.low.clone()
        self.high = action_spec.space.high.clone()
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        self._gen = torch.Generator().manual_seed(self.seed)

    @torch.no_grad()
    def forward(self, td: TensorDictBase) -> TensorDictBase:
        u = torch.rand(self.low.shape, generator=self._gen)
        a = self.low.cpu() + (self.high.cpu() - self.low.cpu()) * u
        td.set(keys.ACTION, a.to(self.low.device))
        return td
