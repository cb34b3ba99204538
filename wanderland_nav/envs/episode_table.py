"""Episodes turned into per-episode tensors once, so resets and steps only index them.

`NavEnv` never touches `Episode` objects on the step path: starts, goals, radii, goal headings,
instruction tokens, goal images and shortest lengths are stacked here (nav frame, `[E, ...]`)
at construction, with errors naming the episode and field when something is unusable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from PIL import Image

MAX_START_SNAP = 1.0  # metres an episode start may lie off the navmesh before it is rejected


@dataclass
class EpisodeTable:
    """Stacked episode data, nav frame, float32 unless stated. E = number of episodes."""

    ids: list  # [E] episode_id as in the file
    start_position: torch.Tensor  # [E, 3] snapped onto the navmesh
    start_yaw: torch.Tensor  # [E]
    goal_position: torch.Tensor  # [E, 3]
    goal_radius: torch.Tensor  # [E]
    goal_yaw: torch.Tensor  # [E] heading of the expert path's last segment
    goal_index: torch.Tensor  # [E] long: row of the goal in the distance field (goals are de-duplicated)
    field_goals_scene: np.ndarray  # [G, 3] float64, scene frame, the distance field's goals
    instruction_tokens: torch.Tensor  # [E, L] int64
    environment: list  # [E] "indoor" | "outdoor" | None

    def __len__(self) -> int:
        return len(self.ids)

    def to(self, device) -> "EpisodeTable":
        for name in ("start_position", "start_yaw", "goal_position", "goal_radius", "goal_yaw", "goal_index",
                     "instruction_tokens"):
            setattr(self, name, getattr(self, name).to(device))
        return self


def encode_instruction(text: str, length: int) -> torch.Tensor:
    """keys.INSTRUCTION_TOKENS: UTF-8 bytes + 1, truncated / right-padded with 0 to `length`. -> int64 `[L]`."""
    b = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)[:length].astype(np.int64) + 1
    out = torch.zeros(length, dtype=torch.int64)
    out[: b.size] = torch.from_numpy(b)
    return out


def build_episode_table(episodes: Sequence, scene, navmesh, *, instruction_length: int, where: str) -> EpisodeTable:
    """Stack `episodes` (scene-frame `Episode`s) for `scene`; `where` names the source in errors."""
    if len(episodes) == 0:
        raise ValueError(f"{where}: no episodes (check the split and the episodes file)")
    R = np.asarray(scene.nav_from_scene, dtype=np.float64)  # nav_from_scene [3, 3]
    starts = np.stack([np.asarray(e.start_position, dtype=np.float64) for e in episodes])  # [E, 3] scene
    goals = np.stack([np.asarray(e.goal_position, dtype=np.float64) for e in episodes])
    for name, arr in (("start_position", starts), ("goals[0].position", goals)):
        bad = np.flatnonzero(~np.isfinite(arr).all(-1))
        if bad.size:
            raise ValueError(f"{where}: episodes[{bad[0]}].{name}: not finite")
    snapped = {}  # field name -> [E, 3] scene frame, on the navmesh
    for name, arr in (("start_position", starts), ("goals[0].position", goals)):
        snapped[name] = _np(navmesh.snap_point(arr, max_distance=1e6))  # judged here, naming the episode
        off = np.linalg.norm(snapped[name] - arr, axis=-1)
        far = np.flatnonzero(~(off <= MAX_START_SNAP))
        if far.size:
            i = far[0]
            raise ValueError(
                f"{where}: episodes[{i}] (id {episodes[i].episode_id}).{name} lies {off[i]:.2f} m from the "
                f"navmesh (> {MAX_START_SNAP} m): episodes and navmesh do not belong together"
            )
    up = scene.up_axis
    start_yaw = np.array([e.start_yaw(up) for e in episodes], dtype=np.float64)
    goal_yaw = np.array([_final_heading(e, R) for e in episodes], dtype=np.float64)
    radius = np.array([e.goal_radius for e in episodes], dtype=np.float64)
    uniq, goal_index = np.unique(np.round(goals, 6), axis=0, return_inverse=True)
    env = [_environment(e, scene) for e in episodes]
    tokens = torch.stack([encode_instruction(e.instruction_text or "", instruction_length) for e in episodes])
    f32 = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    return EpisodeTable(
        ids=[e.episode_id for e in episodes],
        start_position=f32(snapped["start_position"] @ R.T),
        start_yaw=f32(start_yaw),
        goal_position=f32(goals @ R.T),
        goal_radius=f32(radius),
        goal_yaw=f32(goal_yaw),
        goal_index=torch.as_tensor(goal_index.reshape(-1), dtype=torch.long),
        field_goals_scene=uniq,
        instruction_tokens=tokens,
        environment=env,
    )


def load_goal_images(episodes: Sequence, roots: Sequence[Path], height: int, width: int, *, where: str):
    """Goal views named by the episodes' `goal_image` extra (path relative to one of `roots`).

    -> (images uint8 `[E, H, W, 3]` resized to the camera resolution, has bool `[E]`). Episodes
    without the field get zeros and False; a named file that is missing or unreadable is an error.
    """

    E = len(episodes)
    images = torch.zeros(E, height, width, 3, dtype=torch.uint8)
    has = torch.zeros(E, dtype=torch.bool)
    for i, e in enumerate(episodes):  # construction only, never on the step path
        name = e.extras.get("goal_image")
        if not name:
            continue
        cands = [Path(name)] if Path(name).is_absolute() else [Path(r) / name for r in roots]
        path = next((p for p in cands if p.is_file()), None)
        if path is None:
            raise FileNotFoundError(f"{where}: episodes[{i}].goal_image: {name!r} not found under {[str(r) for r in roots]}")
        try:
            with Image.open(path) as im:
                im = im.convert("RGB").resize((width, height), Image.BILINEAR)
                images[i] = torch.from_numpy(np.asarray(im, dtype=np.uint8).copy())
        except OSError as err:
            raise ValueError(f"{where}: episodes[{i}].goal_image: cannot read {path}: {err}") from None
        has[i] = True
    return images, has


def _final_heading(e, R: np.ndarray) -> float:
    """Nav-frame heading of the last non-degenerate segment of the episode's path (start -> goal as fallback)."""
    pts = [np.asarray(e.start_position, dtype=np.float64)[None]]
    for name in ("reference_path", "gt_locations"):
        p = np.asarray(getattr(e, name, np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
        if len(p) >= 2:
            pts = [p]
            break
    p = np.concatenate(pts + [np.asarray(e.goal_position, dtype=np.float64)[None]]) @ R.T
    d = np.diff(p[:, :2], axis=0)
    n = np.linalg.norm(d, axis=-1)
    ok = np.flatnonzero(n > 1e-3)
    if ok.size == 0:
        return float(e.start_yaw_nav) if hasattr(e, "start_yaw_nav") else 0.0
    v = d[ok[-1]]
    return math.atan2(v[1], v[0])


def _environment(e, scene) -> str | None:
    """Episode label for the indoor/outdoor split: the episode's own, else the scene's, else by its start."""
    label = e.extras.get("environment")
    if label in ("indoor", "outdoor"):
        return label
    env = getattr(scene, "environment", None)
    if env in ("indoor", "outdoor"):
        return env
    if env == "mixed":
        inside = scene.is_indoor(np.asarray(e.start_position, dtype=np.float64)[None])
        return "indoor" if bool(np.asarray(inside).reshape(-1)[0]) else "outdoor"
    return None


def _np(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)
