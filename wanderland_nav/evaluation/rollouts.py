"""A compact rollout file (`.npz`): a pure numpy file format (its recorder reads the env, `evaluation/recording.py`).

Why a file of its own: researchers debug a policy by replaying what it did (`python -m
wanderland_nav.replay rollout=<file>`), long after the run; the file keeps only what cannot be
recomputed cheaply (poses, actions, rewards, predicted waypoints, episode ids, per-episode metrics)
and, optionally, the frames. Frames left out are re-rendered from the splats on replay, since the
agent camera is a pure function of the pose and the camera settings stored in `meta`.

Layout (version `ROLLOUT_VERSION`), `T` recorded steps of `B` agents, all poses in the **nav frame**:

| field | dtype, shape | meaning |
|---|---|---|
| `position` | f32 `[T, B, 3]` | agent feet where the action was chosen |
| `yaw` | f32 `[T, B]` | heading (rad, CCW from +x) at that time |
| `next_position`, `next_yaw` | f32 `[T, B, 3]`, `[T, B]` | pose after the step (before any auto-reset) |
| `action` | f32 `[T, B, ...]` | `keys.ACTION` (`[K, 2]` waypoints or `[2]` (v, omega)) |
| `waypoints` | f32 `[T, B, K, 2]` | the policy's predicted body-frame waypoints (= action in waypoint mode) |
| `reward`, `distance_to_goal` | f32 `[T, B]` | step reward; geodesic distance after the step |
| `done`, `success`, `collision` | bool `[T, B]` | episode ended here / ended in the goal / motion blocked |
| `episode_index`, `step_count` | i64 `[T, B]` | episode (index into `episode_ids`); steps taken before |
| `rgb` (optional) | u8 `[T, B, H, W, 3]` | the frame observed at `position` |
| `depth` (optional) | f32 `[T, B, H, W, 1]` | z-depth for `rgb` |
| `pedestrians` (optional) | f32 `[T, B, P, 3]` | nav-frame feet of agent b's people after step t (`env.pedestrians`) |
| `episode_ids` | str `[E]` | `episode_id` of each episode index |
| `meta_json` | str | `RolloutMeta` (version, scene, up axis, camera, control period, metrics of finished episodes) |

Writes are atomic (temporary file + rename); reading checks every field's presence, dtype family
and shape and names the file and field in the error.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError

ROLLOUT_VERSION = 1


class RolloutFormatError(WanderlandInputError):
    """A rollout file is missing, truncated, of another version, or has a field of the wrong shape/type."""


@dataclass
class RolloutMeta:
    """What replay needs besides the arrays: where the scene is and how the camera was set up."""

    version: int = ROLLOUT_VERSION
    scene_root: str | None = None
    episodes_path: str | None = None
    up_axis: str = "+z"
    nav_from_scene: list[list[float]] = field(default_factory=lambda: np.eye(3).tolist())  # [3, 3]
    control_period: float = 0.5  # seconds of simulated time per step (timeline `sim_time`)
    camera: dict[str, Any] = field(default_factory=dict)  # CameraConfig fields (width, height, hfov_deg, ...)
    K: list[list[float]] | None = None  # [3, 3] agent camera intrinsics
    policy: str = "policy"
    metrics: list[dict] = field(default_factory=list)  # EpisodeMetrics.to_dict() of finished episodes
    extras: dict[str, Any] = field(default_factory=dict)


@dataclass
class Rollout:
    """Arrays of one recorded run (see the module docstring for shapes); `rgb`/`depth` may be None."""

    position: np.ndarray
    yaw: np.ndarray
    next_position: np.ndarray
    next_yaw: np.ndarray
    action: np.ndarray
    waypoints: np.ndarray
    reward: np.ndarray
    distance_to_goal: np.ndarray
    done: np.ndarray
    success: np.ndarray
    collision: np.ndarray
    episode_index: np.ndarray
    step_count: np.ndarray
    episode_ids: np.ndarray
    meta: RolloutMeta
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    pedestrians: np.ndarray | None = None

    @property
    def num_steps(self) -> int:
        return int(self.position.shape[0])

    @property
    def num_agents(self) -> int:
        return int(self.position.shape[1])

    def episode_segments(self) -> list[tuple[int, int, int, int]]:
        """`(agent, episode_index, t_start, t_end)` per (possibly unfinished) episode, t_end exclusive.

        An agent's episode starts at its first step or the step after a `done`; contiguous runs of
        steps, so each segment's poses are one trajectory.
        """
        T, B = self.done.shape
        out = []
        for b in range(B):  # loop over agents and their episode boundaries only, not over steps
            ends = np.nonzero(self.done[:, b])[0] + 1
            starts = np.concatenate([[0], ends])
            stops = np.concatenate([ends, [T]])
            for s, e in zip(starts, stops):
                if e > s:
                    out.append((b, int(self.episode_index[s, b]), int(s), int(e)))
        return out


# field -> (dtype kind(s), number of dims, or None if free); T, B checked separately
_FIELDS: dict[str, tuple[str, int | None]] = {
    "position": ("f", 3), "yaw": ("f", 2), "next_position": ("f", 3), "next_yaw": ("f", 2),
    "action": ("f", None), "waypoints": ("f", 4), "reward": ("f", 2), "distance_to_goal": ("f", 2),
    "done": ("b", 2), "success": ("b", 2), "collision": ("b", 2), "episode_index": ("iu", 2),
    "step_count": ("iu", 2),
}
_OPTIONAL = {"rgb": ("u", 5), "depth": ("f", 5), "pedestrians": ("f", 4)}


def save_rollout(path: str | Path, rollout: Rollout, *, compress: bool = True) -> Path:
    """Write `rollout` to `path` (`.npz`) atomically; returns the path."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ValueError(f"{path}: rollout files end in .npz")
    arrays: dict[str, np.ndarray] = {k: np.asarray(getattr(rollout, k)) for k in _FIELDS}
    for k in _OPTIONAL:
        v = getattr(rollout, k)
        if v is not None:
            arrays[k] = np.asarray(v)
    arrays["episode_ids"] = np.asarray([str(e) for e in rollout.episode_ids], dtype=np.str_)
    arrays["meta_json"] = np.asarray(json.dumps(asdict(rollout.meta)))
    _check(arrays, str(path))  # never write a file that the reader would refuse
    with atomic_path(path) as tmp:
        (np.savez_compressed if compress else np.savez)(tmp, **arrays)
    return path


def load_rollout(path: str | Path) -> Rollout:
    """Read and validate a rollout file. Raises `RolloutFormatError` naming the file and the field."""
    path = Path(path)
    if not path.is_file():
        raise RolloutFormatError(f"{path}: no such rollout file")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, zlib.error, OSError, ValueError, EOFError) as e:
        raise RolloutFormatError(f"{path}: not a readable rollout .npz (truncated or corrupt): {e}") from e
    if "meta_json" not in arrays:
        raise RolloutFormatError(f"{path}: field 'meta_json' missing (not a wanderland_nav rollout file)")
    try:
        meta_d = json.loads(str(arrays.pop("meta_json")))
    except json.JSONDecodeError as e:
        raise RolloutFormatError(f"{path}: field 'meta_json' is not valid JSON: {e}") from e
    version = meta_d.get("version")
    if version != ROLLOUT_VERSION:
        raise RolloutFormatError(f"{path}: field 'meta_json.version' is {version!r}; this reader knows "
                                 f"version {ROLLOUT_VERSION}")
    known = {f for f in RolloutMeta.__dataclass_fields__}
    meta = RolloutMeta(**{k: v for k, v in meta_d.items() if k in known})
    _check(arrays, str(path))
    return Rollout(**{k: arrays[k] for k in _FIELDS}, episode_ids=arrays["episode_ids"], meta=meta,
                   rgb=arrays.get("rgb"), depth=arrays.get("depth"), pedestrians=arrays.get("pedestrians"))


def _check(arrays: dict[str, np.ndarray], where: str) -> None:
    if "position" not in arrays:
        raise RolloutFormatError(f"{where}: field 'position' missing")
    TB = arrays["position"].shape[:2]
    if arrays["position"].ndim != 3:
        raise RolloutFormatError(f"{where}: field 'position' has shape {arrays['position'].shape}, expected [T, B, 3]")
    for name, (kinds, ndim) in {**_FIELDS, **_OPTIONAL}.items():
        if name not in arrays:
            if name in _OPTIONAL:
                continue
            raise RolloutFormatError(f"{where}: field {name!r} missing")
        a = arrays[name]
        if a.dtype.kind not in kinds:
            raise RolloutFormatError(f"{where}: field {name!r} has dtype {a.dtype}, expected kind {kinds!r}")
        if (ndim is not None and a.ndim != ndim) or a.shape[:2] != TB:
            raise RolloutFormatError(f"{where}: field {name!r} has shape {a.shape}, "
                                     f"expected [T={TB[0]}, B={TB[1]}, ...]"
                                     + (f" with {ndim} dims" if ndim else ""))
    E = arrays["episode_ids"].shape[0] if "episode_ids" in arrays else None
    if E is None:
        raise RolloutFormatError(f"{where}: field 'episode_ids' missing")
    ei = arrays["episode_index"]
    if ei.size and (ei.min() < 0 or ei.max() >= E):
        raise RolloutFormatError(f"{where}: field 'episode_index' has values outside [0, {E}) (len(episode_ids))")
    if arrays["position"].shape[2:] != (3,):
        raise RolloutFormatError(f"{where}: field 'position' has shape {arrays['position'].shape}, expected [T, B, 3]")
