"""Recording a running `NavEnv` into a `Rollout` (the file format of `wanderland_nav.evaluation.rollouts`).

The recorder sits in the evaluation package, above the env, because it reads the env's TensorDicts and camera;
the file format itself (`rollouts.py`) stays a plain numpy module that replay and viz read without the env.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from wanderland_nav import keys
from wanderland_nav.evaluation.loop import run_evaluation
from wanderland_nav.envs.camera import AgentCamera
from wanderland_nav.envs.config import CameraConfig
from wanderland_nav.envs.experts import waypoints_along_samples
from wanderland_nav.evaluation.rollouts import _FIELDS, Rollout, RolloutMeta, save_rollout
from wanderland_nav.render import render


class RolloutRecorder:
    """Accumulates `(td, td_next)` transitions of a `NavEnv` into a `Rollout`.

    Feed it from any loop: `recorder.add(td_with_action, td_next)` after each `env.step(...)`
    (TorchRL's `step_and_maybe_reset` returns `td` with the post-step state under `"next"`), or wrap
    the env with `RecordingEnv` so that `run_evaluation` feeds it unchanged. Tensors are moved to
    CPU numpy per step (one copy of `[B, ...]`); frames only when `frames=True`.
    """

    def __init__(self, env, *, frames: bool = False, max_steps: int | None = None, policy: str = "policy",
                 episodes_path: str | Path | None = None):
        # a disabled camera delivers all-zero placeholder frames: never store those as if they were images
        cam_on = bool(getattr(getattr(getattr(env, "config", None), "camera", None), "enabled", True))
        self.env, self.frames, self.max_steps = env, bool(frames) and cam_on, max_steps
        self.episodes_path = episodes_path  # the episodes file the env was built from (replay reloads it)
        self.policy = policy
        self._steps: list[dict[str, np.ndarray]] = []
        self.metrics: list[dict] = []

    def __len__(self) -> int:
        return len(self._steps)

    def add(self, td, td_next) -> None:
        """td: TensorDict `[B]` with the observation and `keys.ACTION`; td_next: the post-step TensorDict `[B]`."""
        if self.max_steps is not None and len(self._steps) >= self.max_steps:
            return

        s = step_arrays(td, td_next, self.frames)
        crowd = getattr(self.env, "crowd", None)
        if crowd is not None:  # the people after the step (nav frame), for the replay's moving entities
            s["pedestrians"] = crowd.pos.detach().cpu().numpy().astype(np.float32)
        self._steps.append(s)

    def add_metrics(self, metrics) -> None:
        self.metrics.extend(m.to_dict() if hasattr(m, "to_dict") else dict(m) for m in metrics)

    def rollout(self) -> Rollout:
        if not self._steps:
            raise ValueError("RolloutRecorder: nothing recorded (no env steps were fed)")
        st = {k: np.stack([s[k] for s in self._steps]) for k in self._steps[0]}
        env = self.env
        cam = getattr(getattr(env, "config", None), "camera", None)
        meta = RolloutMeta(
            scene_root=str(getattr(env.scene, "root", "")) or None,
            episodes_path=str(self.episodes_path) if self.episodes_path is not None else None,
            up_axis=str(env.scene.up_axis),
            nav_from_scene=np.asarray(env.scene.nav_from_scene, dtype=float).tolist(),
            control_period=float(env.config.kinematics.control_period),
            camera=asdict(cam) if cam is not None else {},
            K=env.camera.K.cpu().tolist() if getattr(env, "camera", None) is not None else None,
            policy=self.policy, metrics=list(self.metrics),
        )
        ids = np.asarray([str(e.episode_id) for e in env.episodes], dtype=np.str_)
        return Rollout(**{k: st[k].astype(np.float32) if st[k].dtype.kind == "f" else st[k] for k in _FIELDS},
                       episode_ids=ids, meta=meta, rgb=st.get("rgb"), depth=st.get("depth"),
                       pedestrians=st.get("pedestrians"))

    def save(self, path: str | Path) -> Path:
        return save_rollout(path, self.rollout())


def step_arrays(td, td_next, frames: bool) -> dict[str, np.ndarray]:
    """One transition of `B` agents as numpy arrays (the fields of a `Rollout` without the T axis)."""

    def get(t, k, default=None):
        v = t.get(k, None)
        return default if v is None else v.detach().to("cpu")

    action = get(td, keys.ACTION)
    wp = get(td, keys.WAYPOINTS)
    if wp is None:
        wp = action if action.ndim == 3 else torch.zeros(action.shape[0], 0, 2)
    B = action.shape[0]
    false = torch.zeros(B, dtype=torch.bool)
    s = {
        "position": get(td, keys.AGENT_POSITION), "yaw": get(td, keys.AGENT_YAW).reshape(B),
        "next_position": get(td_next, keys.AGENT_POSITION), "next_yaw": get(td_next, keys.AGENT_YAW).reshape(B),
        "action": action, "waypoints": wp,
        "reward": get(td_next, keys.REWARD).reshape(B),
        "distance_to_goal": get(td_next, keys.DISTANCE_TO_GOAL).reshape(B),
        "done": get(td_next, keys.DONE).reshape(B), "success": get(td_next, keys.SUCCESS, false).reshape(B),
        "collision": get(td_next, keys.COLLISION, false).reshape(B),
        "episode_index": get(td, keys.EPISODE_INDEX).reshape(B), "step_count": get(td, keys.STEP_COUNT).reshape(B),
    }
    if frames:
        s["rgb"] = get(td, keys.RGB)[:, -1]  # [B, H, W, 3] the current frame
        d = get(td, keys.DEPTH)
        if d is not None:
            s["depth"] = d[:, -1]
    return {k: v.numpy() for k, v in s.items()}


class RecordingEnv:
    """A transparent proxy over a `NavEnv` that feeds a `RolloutRecorder` from `step_and_maybe_reset`
    and `pop_finished_metrics`. Lets `run_evaluation` (the loop over one env) record without changing it."""

    def __init__(self, env, recorder: RolloutRecorder):
        self._env, self.recorder = env, recorder

    def __getattr__(self, name):
        return getattr(self._env, name)

    def reset(self, *args, **kwargs):
        self.recorder.metrics.clear()  # metrics popped before this reset belong to an earlier run
        return self._env.reset(*args, **kwargs)

    def step_and_maybe_reset(self, td):
        td, td_root = self._env.step_and_maybe_reset(td)
        self.recorder.add(td, td.get("next"))
        return td, td_root

    def pop_finished_metrics(self):
        ms = self._env.pop_finished_metrics()
        self.recorder.add_metrics(ms)
        return ms


def record_evaluation(env, policy, path: str | Path | None, *, num_episodes: int | None = None, seed: int = 0,
                      name: str = "policy", frames: bool = False, progress: bool = False, logger=None,
                      step: int = 0, episodes_path: str | Path | None = None):
    """`run_evaluation` with every transition recorded (the `save_rollouts=` hook of evaluate/train).

    path: where to save the rollout (None: don't); logger: also handed the rollout
    (`logger.log_rollout(rollout, step, tag=name)`, e.g. `RerunLogger`). Returns `(EvaluationResult, Rollout)`.
    """
    rec = RolloutRecorder(env, frames=frames, policy=name, episodes_path=episodes_path)
    res = run_evaluation(RecordingEnv(env, rec), policy, num_episodes, seed=seed, name=name, progress=progress)
    ro = rec.rollout()
    if path is not None:
        save_rollout(path, ro)
    if logger is not None:
        logger.log_rollout(ro, step, tag=name)
    return res, ro


def rollout_from_tensordict(td, meta: RolloutMeta | None = None, episode_ids=None) -> Rollout:
    """A `Rollout` from a TorchRL batch `[B, T]` (a collector's output: observation + action at the root,
    the post-step state under `"next"`). Without `meta`, poses stay in the nav frame (identity)."""
    if td.batch_dims == 1:
        td = td.unsqueeze(0)
    if td.batch_dims != 2:
        raise ValueError(f"rollout_from_tensordict: expected a TensorDict [B, T], got batch size {list(td.batch_size)}")
    B, T = td.batch_size
    steps = td.transpose(0, 1)  # [T, B]
    nxt = steps.get("next")
    frames = keys.RGB in steps.keys()
    per_step = [step_arrays(steps[t], nxt[t], frames) for t in range(T)]  # T views of [B], not per agent
    st = {k: np.stack([s[k] for s in per_step]) for k in per_step[0]}
    E = int(st["episode_index"].max()) + 1 if st["episode_index"].size else 0
    ids = np.asarray([str(i) for i in (episode_ids if episode_ids is not None else range(E))], dtype=np.str_)
    return Rollout(**{k: st[k].astype(np.float32) if st[k].dtype.kind == "f" else st[k] for k in _FIELDS},
                   episode_ids=ids, meta=meta if meta is not None else RolloutMeta(),
                   rgb=st.get("rgb"), depth=st.get("depth"))


def render_rollout_frames(meta: RolloutMeta, gaussians, *, device: str = "cpu", renderer=None,
                          depth: bool | None = None):
    """A frame source `(position_nav [N, 3], yaw [N]) -> (rgb u8 [N, H, W, 3], depth [N, H, W, 1] | None)`
    that renders the agent camera exactly as the env did (same `CameraConfig`, intrinsics, pose formula),
    batched `render_chunk` cameras per renderer call. Replay uses it when a file has no frames."""
    renderer = render if renderer is None else renderer
    known = {f for f in CameraConfig.__dataclass_fields__}
    cfg = CameraConfig(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in meta.camera.items() if k in known})
    cfg.enabled = True
    if depth is not None:
        cfg.depth = bool(depth)
    cam = AgentCamera(cfg, np.asarray(meta.nav_from_scene), renderer, gaussians.to(device), device)

    def frames(position_nav: np.ndarray, yaw: np.ndarray):
        rgb, d = cam.render(torch.as_tensor(position_nav, dtype=torch.float32, device=device),
                            torch.as_tensor(yaw, dtype=torch.float32, device=device))
        return rgb.cpu().numpy(), (None if d is None else d.cpu().numpy())

    return frames




def evaluate_and_record(env, policy, path: str | Path | None, *, num_episodes: int | None = None, seed: int = 0,
                        name: str = "policy", frames: bool = False, progress: bool = False, logger=None,
                        step: int = 0, episodes_path: str | Path | None = None):
    """`run_evaluation`, recorded only when a rollout file (`path`) or a logger wants it. -> EvaluationResult."""
    if path is None and logger is None:
        return run_evaluation(env, policy, num_episodes, seed=seed, name=name, progress=progress)
    res, _ = record_evaluation(env, policy, path, num_episodes=num_episodes, seed=seed, name=name, frames=frames,
                               progress=progress, logger=logger, step=step, episodes_path=episodes_path)
    return res


def expert_rollout(episodes, nav_from_scene: np.ndarray, *, up_axis: str, camera: dict | None = None,
                   control_period: float = 0.5, num_waypoints: int = 5, K=None, stride: int = 1) -> Rollout:
    """The episodes' expert paths as a one-agent `Rollout`, played one after another.

    Each episode contributes its `gt_locations` (dense surface samples, scene frame) as poses; the
    heading at a sample looks toward the next one (the last keeps the previous heading); the
    "predicted" waypoints are the next `num_waypoints` samples in the body frame (what a perfect
    waypoint policy outputs); `distance_to_goal` is the remaining length along the path.
    Replay renders the camera along it, so a researcher sees what the expert saw. `stride` keeps
    every n-th sample (and the last), for long paths or quick looks.
    """
    if stride < 1:
        raise ValueError(f"expert_rollout: stride must be >= 1, got {stride}")
    R_ns = np.asarray(nav_from_scene, np.float64)
    pos, yaw, nxt_pos, nxt_yaw, wps, dist, done, ep_idx, step = [], [], [], [], [], [], [], [], []
    for i, e in enumerate(episodes):  # per episode (not per sample): every line below is batched over its path
        src = e.gt_locations if len(e.gt_locations) >= 2 else e.reference_path
        p = np.asarray(src, np.float64) @ R_ns.T  # [L, 3] nav frame
        p = p[np.unique(np.r_[np.arange(0, len(p), stride), len(p) - 1])]
        if len(p) < 2:
            continue
        d = np.diff(p[:, :2], axis=0)  # [L-1, 2]
        h = np.arctan2(d[:, 1], d[:, 0])
        h = np.concatenate([h, h[-1:]])  # [L]
        seg = np.linalg.norm(np.diff(p, axis=0), axis=-1)
        remain = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])  # [L]
        L = len(p) - 1  # transitions
        wps.append(waypoints_along_samples(p, h[:L], num_waypoints))
        pos.append(p[:L]), yaw.append(h[:L]), nxt_pos.append(p[1:]), nxt_yaw.append(h[1:])
        dist.append(remain[1:]), ep_idx.append(np.full(L, i)), step.append(np.arange(L))
        dn = np.zeros(L, bool)
        dn[-1] = True
        done.append(dn)
    if not pos:
        raise ValueError("expert_rollout: no episode has a path of at least 2 points")
    cat = lambda xs, dt=np.float32: np.concatenate(xs).astype(dt)[:, None]  # noqa: E731  [T, 1, ...]
    wp = cat(wps)
    T = wp.shape[0]
    meta = RolloutMeta(up_axis=up_axis, nav_from_scene=R_ns.tolist(), control_period=control_period,
                       camera=dict(camera or {}), K=None if K is None else np.asarray(K, float).tolist(),
                       policy="expert")
    return Rollout(position=cat(pos), yaw=cat(yaw), next_position=cat(nxt_pos), next_yaw=cat(nxt_yaw),
                   action=wp.copy(), waypoints=wp, reward=np.zeros((T, 1), np.float32), distance_to_goal=cat(dist),
                   done=cat(done, bool), success=cat(done, bool), collision=np.zeros((T, 1), bool),
                   episode_index=cat(ep_idx, np.int64), step_count=cat(step, np.int64),
                   episode_ids=np.asarray([str(e.episode_id) for e in episodes], dtype=np.str_), meta=meta)
