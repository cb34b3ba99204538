"""The episodes.json schema (VLN-CE-Isaac, as Wanderland releases it) with strict validation.

On disk::

    {"episodes": [
        {"episode_id": 0, "scene_id": "demo",
         "start_position": [x, y, z],            # scene frame, metres
         "start_rotation": [x, y, z, w],         # xyzw on disk (wxyz inside the code)
         "geodesic_distance": 12.3,              # metres along the navmesh (also read from info.geodesic_distance)
         "goals": [{"position": [x, y, z], "radius": 3.0}],
         "instruction": {"instruction_text": "..."},   # a plain string is accepted on read
         "reference_path": [[x, y, z], ...],     # shortest-path corners, start .. goal
         "gt_locations": [[x, y, z], ...],       # the expert path resampled densely on the surface
         "gt_steps": 48,
         ... extras (split, goal_image, up_axis, euclidean_distance, island, ...) ...},
     ...],
     ... optional top-level extras ...}

Reading a released Wanderland file and writing ours go through the same code, so the
framework can never produce a file it could not read back. Unknown fields are *extras*: kept
in order and written back unchanged, because downstream tools (VLN-CE, Wanderland's own
evaluation) put their own bookkeeping there and a round trip must not lose it.

Every problem raises `EpisodeFormatError` naming the file, the episode index and the field,
e.g. ``data/x/episodes.json: episodes[3].goals[0].radius: must be > 0, got -1.0``.

Heading convention of `start_rotation`: a rotation about the scene's up axis. With
`R_ns = nav_from_scene_rotation(up)`, the quaternion is `R_sn @ Rz(yaw) @ R_ns`, i.e. yaw is the
heading in the nav frame (0 = nav +x, counter-clockwise seen from above) and the agent's
forward vector in the scene frame is `R(q) @ (R_sn @ [1, 0, 0])`. For a +z-up scene this is the
Isaac Sim convention (forward +x, yaw about +z). Use `rotation_from_yaw` / `yaw_from_rotation`.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from wanderland_nav.atomic import atomic_write_bytes
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import nav_from_scene_rotation, parse_up_axis
from wanderland_nav.geometry import up_vector

#: The fields this schema owns, in the order they are written. Everything else is an extra.
CORE_FIELDS = (
    "episode_id",
    "scene_id",
    "start_position",
    "start_rotation",
    "geodesic_distance",
    "goals",
    "instruction",
    "reference_path",
    "gt_locations",
    "gt_steps",
)
#: An instruction shorter than this (in words) is not a route description.
MIN_INSTRUCTION_WORDS = 3
#: |q| of start_rotation may deviate from 1 by this much (files store ~6 decimals).
QUAT_NORM_TOL = 1e-3
SPLITS = ("train", "val", "test")


class EpisodeFormatError(WanderlandInputError):
    """An episodes file (or an Episode built in code) does not follow the schema."""


# --------------------------------------------------------------------------- data model


@dataclass
class Goal:
    """One goal: `position [3]` (scene frame, metres) and the success `radius` (metres)."""

    position: np.ndarray  # [3] float64, scene frame
    radius: float
    extras: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"position": _floats(self.position), "radius": float(self.radius), **self.extras}


@dataclass
class Episode:
    """One navigation episode; positions in the scene frame of `scene_id`'s scene.

    `start_rotation_wxyz` is wxyz like every quaternion inside the code; it is written as
    `start_rotation` in xyzw. `extras` holds every non-schema field (split, goal_image,
    up_axis, euclidean_distance, island, trajectory_id, info, ...) in file order.
    """

    episode_id: int | str
    scene_id: str
    start_position: np.ndarray  # [3] float64, scene frame
    start_rotation_wxyz: np.ndarray  # [4] float64, unit, rotation about the scene's up axis
    geodesic_distance: float  # metres along the navmesh
    goals: list[Goal]
    instruction_text: str
    reference_path: np.ndarray  # [P, 3] float64, corners start .. goal
    gt_locations: np.ndarray  # [L, 3] float64, dense samples on the surface
    gt_steps: int
    instruction_extras: dict[str, Any] = field(default_factory=dict)  # e.g. instruction_tokens
    extras: dict[str, Any] = field(default_factory=dict)

    # ----------------------------------------------------------------- conveniences

    @property
    def goal_position(self) -> np.ndarray:
        """`[3]` position of the first goal (the one point-goal tasks use)."""
        return self.goals[0].position

    @property
    def goal_radius(self) -> float:
        return float(self.goals[0].radius)

    @property
    def split(self) -> str | None:
        return self.extras.get("split")

    @property
    def start_rotation_xyzw(self) -> np.ndarray:
        return self.start_rotation_wxyz[[1, 2, 3, 0]]

    def start_yaw(self, up_axis: str) -> float:
        """Nav-frame heading (rad) of the start rotation, see the module docstring."""
        return float(yaw_from_rotation(self.start_rotation_wxyz, up_axis))

    # ----------------------------------------------------------------- (de)serialisation

    def to_dict(self) -> dict[str, Any]:
        """The on-disk dict: schema fields in `CORE_FIELDS` order, then extras in their order."""
        d: dict[str, Any] = {
            "episode_id": self.episode_id,
            "scene_id": self.scene_id,
            "start_position": _floats(self.start_position),
            "start_rotation": _floats(self.start_rotation_xyzw),
            "geodesic_distance": float(self.geodesic_distance),
            "goals": [g.to_dict() for g in self.goals],
            "instruction": {"instruction_text": self.instruction_text, **self.instruction_extras},
            "reference_path": [_floats(p) for p in self.reference_path],
            "gt_locations": [_floats(p) for p in self.gt_locations],
            "gt_steps": int(self.gt_steps),
        }
        d.update(self.extras)
        return d

    @classmethod
    def from_dict(cls, d: Any, *, where: str = "episode") -> "Episode":
        """Parse and validate one episode dict; errors start with `where` (file + index)."""
        if not isinstance(d, dict):
            raise EpisodeFormatError(f"{where}: must be an object, got {type(d).__name__}")
        for name in ("episode_id", "scene_id", "start_position", "start_rotation", "goals",
                     "instruction", "reference_path", "gt_locations", "gt_steps"):
            if name not in d:
                raise EpisodeFormatError(f"{where}.{name}: missing required field")
        extras = {k: v for k, v in d.items() if k not in CORE_FIELDS}
        if "geodesic_distance" in d:
            geo = d["geodesic_distance"]
            geo_where = f"{where}.geodesic_distance"
        elif isinstance(d.get("info"), dict) and "geodesic_distance" in d["info"]:
            # VLN-CE / Habitat keep it under info; read it there, leave `info` as an extra.
            geo = d["info"]["geodesic_distance"]
            geo_where = f"{where}.info.geodesic_distance"
        else:
            raise EpisodeFormatError(f"{where}.geodesic_distance: missing required field "
                                     "(neither top-level nor info.geodesic_distance)")
        text, instr_extras = _parse_instruction(d["instruction"], f"{where}.instruction")
        goals_raw = d["goals"]
        if not isinstance(goals_raw, list) or not goals_raw:
            raise EpisodeFormatError(f"{where}.goals: must be a non-empty list of {{position, radius}}")
        goals = [_parse_goal(g, f"{where}.goals[{j}]") for j, g in enumerate(goals_raw)]
        q_xyzw = _vec(d["start_rotation"], 4, f"{where}.start_rotation")
        ep = cls(
            episode_id=_episode_id(d["episode_id"], f"{where}.episode_id"),
            scene_id=_string(d["scene_id"], f"{where}.scene_id"),
            start_position=_vec(d["start_position"], 3, f"{where}.start_position"),
            start_rotation_wxyz=q_xyzw[[3, 0, 1, 2]],
            geodesic_distance=_nonneg(geo, geo_where),
            goals=goals,
            instruction_text=text,
            reference_path=_points(d["reference_path"], f"{where}.reference_path", min_len=1),
            gt_locations=_points(d["gt_locations"], f"{where}.gt_locations", min_len=1),
            gt_steps=_count(d["gt_steps"], f"{where}.gt_steps"),
            instruction_extras=instr_extras,
            extras=extras,
        )
        ep.validate(where=where)
        return ep

    def validate(self, *, where: str = "episode") -> None:
        """Cross-field checks, also run on episodes built in code before they are saved."""
        q = np.asarray(self.start_rotation_wxyz, dtype=np.float64)
        if q.shape != (4,) or not np.isfinite(q).all():
            raise EpisodeFormatError(f"{where}.start_rotation: must be 4 finite numbers")
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > QUAT_NORM_TOL:
            raise EpisodeFormatError(f"{where}.start_rotation: quaternion must be unit length, |q| = {n:.6g}")
        for name in ("start_position",):
            v = np.asarray(getattr(self, name))
            if v.shape != (3,) or not np.isfinite(v).all():
                raise EpisodeFormatError(f"{where}.{name}: must be 3 finite numbers")
        for name in ("reference_path", "gt_locations"):
            v = np.asarray(getattr(self, name))
            if v.ndim != 2 or v.shape[1] != 3 or len(v) < 1 or not np.isfinite(v).all():
                raise EpisodeFormatError(f"{where}.{name}: must be a non-empty list of finite [x, y, z]")
        if not self.goals:
            raise EpisodeFormatError(f"{where}.goals: must be non-empty")
        if not (math.isfinite(self.geodesic_distance) and self.geodesic_distance >= 0):
            raise EpisodeFormatError(f"{where}.geodesic_distance: must be finite and >= 0, got {self.geodesic_distance}")
        if len(self.instruction_text.split()) < MIN_INSTRUCTION_WORDS:
            raise EpisodeFormatError(
                f"{where}.instruction.instruction_text: needs at least {MIN_INSTRUCTION_WORDS} words, "
                f"got {self.instruction_text!r}")
        split = self.extras.get("split")
        if split is not None and split not in SPLITS:
            raise EpisodeFormatError(f"{where}.split: must be one of {SPLITS}, got {split!r}")
        up = self.extras.get("up_axis")
        if up is not None:
            try:
                parse_up_axis(up)
            except ValueError as e:
                raise EpisodeFormatError(f"{where}.up_axis: {e}") from None


@dataclass
class EpisodeFile:
    """A whole file: the episodes plus any top-level extras (kept on round trip)."""

    episodes: list[Episode]
    extras: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- file I/O


def read_episode_bytes(path: str | os.PathLike) -> bytes:
    """The JSON bytes of an episodes file (`.json.gz` decompressed)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: episodes file not found")
    raw = path.read_bytes()
    if path.suffix == ".gz":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as e:  # a truncated .gz raises EOFError
            raise EpisodeFormatError(f"{path}: not a valid gzip file ({e})") from None
    return raw


def write_episode_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write JSON bytes atomically; `.json.gz` is gzipped with a fixed mtime (byte-identical)."""
    path = Path(path)
    if path.suffix == ".gz":
        data = gzip.compress(data, compresslevel=6, mtime=0)
    atomic_write_bytes(path, data)
    return path


def load_episode_file(path: str | os.PathLike) -> EpisodeFile:
    """Read and validate `episodes.json` (or `.json.gz`); errors name the file, index and field."""
    path = Path(path)
    raw = read_episode_bytes(path)
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise EpisodeFormatError(f"{path}: not valid JSON ({e})") from None
    return parse_episode_file(data, source=str(path))


def parse_episode_file(data: Any, *, source: str = "<episodes>") -> EpisodeFile:
    """Validate an already-decoded top-level object."""
    if not isinstance(data, dict):
        raise EpisodeFormatError(f"{source}: top level must be an object with an 'episodes' list, "
                                 f"got {type(data).__name__}")
    if "episodes" not in data:
        raise EpisodeFormatError(f"{source}: episodes: missing required top-level field")
    eps = data["episodes"]
    if not isinstance(eps, list):
        raise EpisodeFormatError(f"{source}: episodes: must be a list, got {type(eps).__name__}")
    episodes = [Episode.from_dict(e, where=f"{source}: episodes[{i}]") for i, e in enumerate(eps)]
    _check_unique_ids(episodes, source)
    return EpisodeFile(episodes=episodes, extras={k: v for k, v in data.items() if k != "episodes"})


def load_episodes(path: str | os.PathLike, *, split: str | None = None) -> list[Episode]:
    """The episodes of a file, optionally only those whose extra `split` equals `split`."""
    eps = load_episode_file(path).episodes
    if split is None:
        return eps
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS} or None, got {split!r}")
    return [e for e in eps if e.extras.get("split") == split]


def dump_episodes(episodes: Sequence[Episode], extras: dict[str, Any] | None = None, *,
                  source: str = "<episodes>") -> bytes:
    """The exact bytes `save_episodes` writes (deterministic: field order fixed, no timestamps)."""
    for i, ep in enumerate(episodes):
        ep.validate(where=f"{source}: episodes[{i}]")
    _check_unique_ids(list(episodes), source)
    obj: dict[str, Any] = {"episodes": [ep.to_dict() for ep in episodes]}
    for k, v in (extras or {}).items():
        if k == "episodes":
            raise EpisodeFormatError(f"{source}: top-level extra may not be called 'episodes'")
        obj[k] = v
    try:
        text = json.dumps(obj, indent=1, allow_nan=False, ensure_ascii=False)
    except (TypeError, ValueError) as e:
        raise EpisodeFormatError(f"{source}: cannot serialise to JSON ({e})") from None
    return (text + "\n").encode("utf-8")


def save_episodes(path: str | os.PathLike, episodes: Sequence[Episode],
                  extras: dict[str, Any] | None = None) -> Path:
    """Validate and write atomically; `.json.gz` is gzipped with a fixed mtime (byte-identical)."""
    return write_episode_bytes(path, dump_episodes(episodes, extras, source=str(path)))


# --------------------------------------------------------------------------- headings


def rotation_from_yaw(yaw_nav, up_axis: str) -> np.ndarray:
    """Nav-frame headings `[...]` (rad) -> scene-frame wxyz quaternions `[..., 4]` about the up axis.

    The rotation by `yaw` about nav +z is `R_sn Rz R_ns` in the scene frame, i.e. a rotation by
    `yaw` about the scene's up vector, so the quaternion is `(cos(yaw/2), sin(yaw/2) * up)`.
    """

    yaw = np.asarray(yaw_nav, dtype=np.float64)
    up = up_vector(up_axis)
    half = 0.5 * yaw
    return np.concatenate([np.cos(half)[..., None], np.sin(half)[..., None] * up], axis=-1)


def yaw_from_rotation(q_wxyz, up_axis: str) -> np.ndarray:
    """Inverse of `rotation_from_yaw`: the nav-frame heading of the agent's forward vector.

    Works for any rotation (not only pure yaw): the forward axis `R(q) @ (R_sn @ e_x)` is projected
    onto the nav ground plane. Returns `[...]` radians in [-pi, pi].
    """
    q = np.asarray(q_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    R_ns = nav_from_scene_rotation(up_axis)
    f0 = R_ns.T @ np.array([1.0, 0.0, 0.0])  # nav +x in the scene frame
    w, v = q[..., :1], q[..., 1:]
    # rotate f0 by q: f = f0 + 2w (v x f0) + 2 v x (v x f0)
    t = 2.0 * np.cross(v, np.broadcast_to(f0, v.shape))
    f = f0 + w * t + np.cross(v, t)
    f_nav = f @ R_ns.T
    return np.arctan2(f_nav[..., 1], f_nav[..., 0])


# --------------------------------------------------------------------------- field parsers


def _floats(v: Iterable[float]) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=np.float64).ravel()]


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _vec(v: Any, n: int, where: str) -> np.ndarray:
    if not isinstance(v, (list, tuple)) or len(v) != n or not all(_is_number(x) for x in v):
        raise EpisodeFormatError(f"{where}: must be a list of {n} numbers, got {_short(v)}")
    a = np.asarray(v, dtype=np.float64)
    if not np.isfinite(a).all():
        raise EpisodeFormatError(f"{where}: must be finite, got {_short(v)}")
    return a


def _points(v: Any, where: str, *, min_len: int) -> np.ndarray:
    if not isinstance(v, list) or len(v) < min_len:
        raise EpisodeFormatError(f"{where}: must be a list of at least {min_len} [x, y, z] points, got {_short(v)}")
    return np.stack([_vec(p, 3, f"{where}[{k}]") for k, p in enumerate(v)]).reshape(-1, 3)


def _nonneg(x: Any, where: str) -> float:
    if not _is_number(x) or not math.isfinite(x) or x < 0:
        raise EpisodeFormatError(f"{where}: must be a finite number >= 0, got {_short(x)}")
    return float(x)


def _count(x: Any, where: str) -> int:
    if isinstance(x, bool) or not isinstance(x, int) or x < 0:
        raise EpisodeFormatError(f"{where}: must be an integer >= 0, got {_short(x)}")
    return int(x)


def _string(x: Any, where: str) -> str:
    if not isinstance(x, str) or not x:
        raise EpisodeFormatError(f"{where}: must be a non-empty string, got {_short(x)}")
    return x


def _episode_id(x: Any, where: str) -> int | str:
    if isinstance(x, bool) or not isinstance(x, (int, str)) or x == "":
        raise EpisodeFormatError(f"{where}: must be an integer or a non-empty string, got {_short(x)}")
    return x


def _parse_goal(g: Any, where: str) -> Goal:
    if not isinstance(g, dict):
        raise EpisodeFormatError(f"{where}: must be an object {{position, radius}}, got {_short(g)}")
    if "position" not in g:
        raise EpisodeFormatError(f"{where}.position: missing required field")
    if "radius" not in g:
        raise EpisodeFormatError(f"{where}.radius: missing required field")
    r = g["radius"]
    if not _is_number(r) or not math.isfinite(r) or r <= 0:
        raise EpisodeFormatError(f"{where}.radius: must be a finite number > 0, got {_short(r)}")
    return Goal(position=_vec(g["position"], 3, f"{where}.position"), radius=float(r),
                extras={k: v for k, v in g.items() if k not in ("position", "radius")})


def _parse_instruction(x: Any, where: str) -> tuple[str, dict[str, Any]]:
    if isinstance(x, str):
        return x, {}
    if not isinstance(x, dict):
        raise EpisodeFormatError(f"{where}: must be an object with instruction_text or a string, got {_short(x)}")
    if "instruction_text" not in x:
        raise EpisodeFormatError(f"{where}.instruction_text: missing required field")
    text = x["instruction_text"]
    if not isinstance(text, str):
        raise EpisodeFormatError(f"{where}.instruction_text: must be a string, got {_short(text)}")
    return text, {k: v for k, v in x.items() if k != "instruction_text"}


def _check_unique_ids(episodes: list[Episode], source: str) -> None:
    seen: dict[Any, int] = {}
    for i, ep in enumerate(episodes):
        key = (ep.scene_id, ep.episode_id)
        if key in seen:
            raise EpisodeFormatError(f"{source}: episodes[{i}].episode_id: duplicate {ep.episode_id!r} in scene "
                                     f"{ep.scene_id!r} (first at episodes[{seen[key]}])")
        seen[key] = i


def _short(x: Any, n: int = 60) -> str:
    s = repr(x)
    return s if len(s) <= n else s[: n - 3] + "..."
