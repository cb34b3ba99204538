"""Log a recorded rollout to rerun: per step and per agent, the pose, the camera with what it saw,
the predicted waypoints, reward, distance to goal; per finished episode, its metrics.

Timelines: `step` (sequence, the rollout's step index) and `sim_time` (duration, `step * control_period`).
Entity paths (under `prefix`, default `world`; plots under `plots_prefix`):

* `world/agents/agent_<b>`: `Transform3D` world <- body (feet, x forward, z up), one per step;
* `world/agents/agent_<b>/camera`: static body <- camera transform and `Pinhole` (OpenCV axes), `Image`
  per step (and `camera/depth`: `DepthImage` when depth is present);
* `world/agents/agent_<b>/waypoints`: the policy's predicted body-frame waypoints, per step;
* `world/pedestrians/agent_<b>`: agent b's people (`env.pedestrians`) as points at waist height, per step;
* `world/trajectories/agent_<b>/ep_<id>_<k>`: the realised path of the k-th episode segment of that agent,
  shown from its first step (cleared when the next episode starts);
* `plots/reward/agent_<b>`, `plots/distance_to_goal/agent_<b>`: scalars per step;
* `plots/metrics/{NE, success, SPL, path_length}` at the step each episode ended, and
  `plots/metrics/mean_{NE, SR, SPL, IR}` running means over the episodes ended so far.

Why columns (`send_columns`): a rollout is logged as one batch per entity, not one call per step,
so logging T steps costs a handful of calls per agent.
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from typing import Callable

import numpy as np
import rerun as rr
import torch

from wanderland_nav.geometry import agent_camera_poses, yaw_rotation
from wanderland_nav.evaluation.rollouts import Rollout
from wanderland_nav.viz.rerun_episodes import entity_name
from wanderland_nav.viz.rerun_scene import view_coordinates

FrameSource = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray | None]]
"""`(position_nav [N, 3], yaw [N]) -> (rgb uint8 [N, H, W, 3], depth float32 [N, H, W, 1] or None)`."""


def body_poses_scene(position_nav: np.ndarray, yaw: np.ndarray, nav_from_scene: np.ndarray):
    """World <- body in the scene frame: `(translation [..., 3], rotation [..., 3, 3])`.

    body = nav frame rotated by yaw about +z at the feet; scene = R_sn @ nav with R_sn = nav_from_scene^T.
    """
    R_sn = np.asarray(nav_from_scene, np.float64).T
    return position_nav @ R_sn.T, R_sn @ yaw_rotation(np.asarray(yaw))


def body_from_camera(mount_height: float, pitch_deg: float) -> np.ndarray:
    """`[4, 4]` body <- camera (OpenCV axes) for the env's head camera: the same formula the env renders
    with (`geometry.agent_camera_poses` at the origin, yaw 0, nav = scene)."""
    T = agent_camera_poses(torch.zeros(3, dtype=torch.float64), torch.zeros((), dtype=torch.float64),
                           height=float(mount_height), pitch=math.radians(float(pitch_deg)),
                           nav_from_scene=np.eye(3))
    return T.numpy()


def _times(steps: np.ndarray, dt: float, timeline: str, fixed: dict[str, int]) -> list:
    """Index columns: `timeline` = steps, `sim_time` = steps * dt, plus constant `fixed` sequences."""
    steps = np.asarray(steps, np.int64)
    return [rr.TimeColumn(timeline, sequence=steps), rr.TimeColumn("sim_time", duration=steps * float(dt)),
            *(rr.TimeColumn(k, sequence=np.full(len(steps), int(v))) for k, v in fixed.items())]


def _set_time(rec, t: int, dt: float, timeline: str, fixed: dict[str, int]) -> None:
    rec.set_time(timeline, sequence=int(t))
    rec.set_time("sim_time", duration=float(t) * dt)
    for k, v in fixed.items():
        rec.set_time(k, sequence=int(v))


def _image_format(h: int, w: int, channels: int, dtype: str):
    if channels == 3:
        return rr.components.ImageFormat(width=w, height=h, color_model="RGB", channel_datatype=dtype)
    return rr.components.ImageFormat(width=w, height=h, channel_datatype=dtype)


def log_rollout(rec: rr.RecordingStream, rollout: Rollout, *, frames: FrameSource | None = None,
                prefix: str = "world", plots_prefix: str = "plots", agents: list[int] | None = None,
                step_offset: int = 0, log_frames: bool = True, view_coords: bool = True,
                timeline: str = "step", fixed_times: dict[str, int] | None = None, frame_chunk: int = 64) -> dict:
    """Log `rollout` (see the module docstring for entities). Returns counts (`steps`, `agents`, `episodes`).

    frames: renders the frames when `rollout.rgb` is None (replay re-renders from the splats); with
        neither, the camera frustum is logged without images.
    agents: which agents to log (default all).
    step_offset: added to the step timeline.
    timeline / fixed_times: name of the per-step timeline, and other timelines held constant for this
        rollout (the training logger logs eval rollouts on `rollout_step` at a fixed training `step`).
    frame_chunk: steps rendered (and sent) per batch when frames are re-rendered; bounds the memory
        held for frames to `frame_chunk * len(agents)` images instead of the whole rollout.
    """
    fixed = dict(fixed_times or {})
    T, B = rollout.num_steps, rollout.num_agents
    meta = rollout.meta
    agents = list(range(B)) if agents is None else [int(b) for b in agents]
    dt = float(meta.control_period)
    if view_coords:
        rec.log(prefix, view_coordinates(meta.up_axis), static=True)
    trans, rot = body_poses_scene(rollout.position.astype(np.float64), rollout.yaw.astype(np.float64),
                                  np.asarray(meta.nav_from_scene))  # [T, B, 3], [T, B, 3, 3]
    cam = meta.camera or {}
    K = np.asarray(meta.K, np.float64) if meta.K is not None else None
    body_T_cam = body_from_camera(cam.get("mount_height", 1.2), cam.get("pitch_deg", 0.0))
    idx = _times(np.arange(step_offset, step_offset + T), dt, timeline, fixed)
    for b in agents:  # a handful of agents; every entity below is one batched call over T steps
        base = f"{prefix}/agents/agent_{b}"
        rr.send_columns(base, indexes=idx, columns=rr.Transform3D.columns(translation=trans[:, b], mat3x3=rot[:, b]),
                        recording=rec)
        if K is not None:
            w, h = int(cam.get("width", 2 * K[0, 2])), int(cam.get("height", 2 * K[1, 2]))
            rec.log(f"{base}/camera", rr.Transform3D(translation=body_T_cam[:3, 3], mat3x3=body_T_cam[:3, :3]),
                    static=True)
            rec.log(f"{base}/camera", rr.Pinhole(image_from_camera=K.astype(np.float32), resolution=[w, h],
                                                 camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.4),
                    static=True)
        wp = rollout.waypoints[:, b]  # [T, K, 2] body frame
        if wp.shape[1]:
            K_wp = wp.shape[1]
            pts = np.concatenate([wp, np.zeros((*wp.shape[:2], 1), wp.dtype)], -1).reshape(-1, 3)
            rr.send_columns(f"{base}/waypoints", indexes=idx,
                            columns=rr.Points3D.columns(positions=pts).partition([K_wp] * T), recording=rec)
            rec.log(f"{base}/waypoints", rr.Points3D.from_fields(colors=[[60, 140, 255]], radii=0.08), static=True)
        if rollout.pedestrians is not None:  # agent b's people: moving points, one batched call over T steps
            people = rollout.pedestrians[:, b].astype(np.float64) + [0.0, 0.0, 0.9]  # nav, at the waist
            people = people @ np.asarray(meta.nav_from_scene, np.float64)
            P = people.shape[1]
            rr.send_columns(f"{prefix}/pedestrians/agent_{b}", indexes=idx, recording=rec,
                            columns=rr.Points3D.columns(positions=people.reshape(-1, 3)).partition([P] * T))
            rec.log(f"{prefix}/pedestrians/agent_{b}", rr.Points3D.from_fields(colors=[[255, 120, 40]], radii=0.3),
                    static=True)
        for name in ("reward", "distance_to_goal"):
            rr.send_columns(f"{plots_prefix}/{name}/agent_{b}", indexes=idx,
                            columns=rr.Scalars.columns(scalars=getattr(rollout, name)[:, b].astype(np.float64)),
                            recording=rec)
    if log_frames:
        _log_frames(rec, rollout, frames, agents, prefix, step_offset, dt, timeline, fixed, frame_chunk)
    n_ep = _log_trajectories(rec, rollout, trans, agents, prefix, step_offset, dt, timeline, fixed)
    _log_episode_metrics(rec, rollout, agents, plots_prefix, step_offset, dt, timeline, fixed)
    rec.reset_time()  # later logs on this stream must not inherit the last step's time
    return {"steps": T, "agents": len(agents), "episodes": n_ep}


def _log_frames(rec, rollout: Rollout, frames: FrameSource | None, agents, prefix, t0, dt, timeline, fixed,
                frame_chunk: int) -> None:
    """Camera images (and depth) per agent: the stored frames, or `frames(...)` renders, sent in chunks
    of `frame_chunk` steps (one `send_columns` per agent and chunk)."""
    T = rollout.num_steps
    if rollout.rgb is None and frames is None:
        return
    sel = np.asarray(agents)
    formats_sent = False
    for s in range(0, T, max(1, int(frame_chunk))):
        e = min(T, s + max(1, int(frame_chunk)))
        if rollout.rgb is not None:
            rgb = rollout.rgb[s:e][:, sel]  # [t, A, H, W, 3]
            depth = None if rollout.depth is None else rollout.depth[s:e][:, sel]
        else:
            r, d = frames(rollout.position[s:e][:, sel].reshape(-1, 3), rollout.yaw[s:e][:, sel].reshape(-1))
            rgb = r.reshape(e - s, len(sel), *r.shape[1:])
            depth = None if d is None else d.reshape(e - s, len(sel), *d.shape[1:])
        idx = _times(np.arange(t0 + s, t0 + e), dt, timeline, fixed)
        H, W = rgb.shape[2:4]
        for i, b in enumerate(agents):
            base = f"{prefix}/agents/agent_{b}/camera"
            if not formats_sent:
                rec.log(base, rr.Image.from_fields(format=_image_format(H, W, 3, "U8")), static=True)
                if depth is not None:
                    rec.log(f"{base}/depth", rr.DepthImage.from_fields(format=_image_format(H, W, 1, "F32"),
                                                                       meter=1.0), static=True)
            rr.send_columns(base, indexes=idx, recording=rec,
                            columns=rr.Image.columns(buffer=np.ascontiguousarray(rgb[:, i]).reshape(e - s, -1)))
            if depth is not None:
                rr.send_columns(f"{base}/depth", indexes=idx, recording=rec,
                                columns=rr.DepthImage.columns(buffer=np.ascontiguousarray(depth[:, i], np.float32)
                                                              .reshape(e - s, -1)))
        formats_sent = True


def _log_trajectories(rec, rollout: Rollout, trans: np.ndarray, agents, prefix, t0, dt, timeline, fixed) -> int:
    """Each episode segment's realised path (scene frame), visible from its first to its last step."""
    next_trans, _ = body_poses_scene(rollout.next_position.astype(np.float64), rollout.next_yaw.astype(np.float64),
                                     np.asarray(rollout.meta.nav_from_scene))
    keep = set(agents)
    n = 0
    for k, (b, ep, s, e) in enumerate(rollout.episode_segments()):  # one per episode, not per step
        if b not in keep:
            continue
        path = np.concatenate([trans[s:e, b], next_trans[e - 1:e, b]])  # poses, then where the last step ended
        ent = f"{prefix}/trajectories/agent_{b}/{entity_name(rollout.episode_ids[ep])}_{k}"
        _set_time(rec, t0 + s, dt, timeline, fixed)
        rec.log(ent, rr.LineStrips3D([path], colors=[[0, 200, 255]], radii=0.05))
        if e < rollout.num_steps:
            _set_time(rec, t0 + e, dt, timeline, fixed)
            rec.log(ent, rr.Clear(recursive=False))
        n += 1
    return n


def _log_episode_metrics(rec, rollout: Rollout, agents, plots_prefix, t0, dt, timeline, fixed) -> None:
    """NE / success / SPL / path length at each finished episode's last step, plus running means.

    Uses the env's own `EpisodeMetrics` (in `meta.metrics`) when they match the segment (same
    episode index and step count, in end order), else what the arrays say (NE, success, path length).
    """
    by_key: dict[tuple[int, int], deque] = defaultdict(deque)
    for m in rollout.meta.metrics:
        by_key[(int(m.get("episode_index", -1)), int(m.get("steps", -1)))].append(m)
    moved = np.linalg.norm(rollout.next_position - rollout.position, axis=-1)  # [T, B] metres (nav frame)
    keep = set(agents)
    rows = []
    for b, ep, s, e in rollout.episode_segments():
        if b not in keep or not rollout.done[e - 1, b]:
            continue
        steps = int(rollout.step_count[s, b]) + (e - s)
        m = by_key[(ep, steps)].popleft() if by_key[(ep, steps)] else None
        if m is not None:
            rows.append((e - 1, m["navigation_error"], float(m["success"]), m["spl"], m["path_length"],
                         float(m["intervention"])))
        else:
            rows.append((e - 1, float(rollout.distance_to_goal[e - 1, b]), float(rollout.success[e - 1, b]),
                         float("nan"), float(moved[s:e, b].sum()), float("nan")))
    if not rows:
        return
    rows.sort(key=lambda r: r[0])
    a = np.asarray(rows, np.float64)  # [N, 6]: t, NE, success, SPL, path_length, intervention
    idx = _times((a[:, 0] + t0).astype(np.int64), dt, timeline, fixed)
    cnt = np.arange(1, len(a) + 1)
    series = {"NE": a[:, 1], "success": a[:, 2], "SPL": a[:, 3], "path_length": a[:, 4],
              "mean_NE": np.cumsum(a[:, 1]) / cnt, "mean_SR": np.cumsum(a[:, 2]) / cnt,
              "mean_SPL": np.cumsum(a[:, 3]) / cnt, "mean_IR": np.cumsum(a[:, 5]) / cnt}
    for k, v in series.items():
        if np.isfinite(v).any():
            rr.send_columns(f"{plots_prefix}/metrics/{k}", indexes=idx, columns=rr.Scalars.columns(scalars=v),
                            recording=rec)
