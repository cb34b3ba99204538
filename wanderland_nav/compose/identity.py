"""Run identity: what a result was computed from, so an old result is never shown for a new run.

identity = hash(resolved config minus cosmetic keys) + hash(scene: its path and the hashes of the
prepared artefacts the run reads). It goes into every checkpoint and result row; the default run
folder carries its short form (`outputs/<experiment>/<hash>_seed<seed>`), so a sweep over a setting
gets one folder per value; resuming a folder made by another identity refuses and says what differs.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np

from wanderland_nav.cache import file_sha256

#: keys that change how a run looks, not what it computes (dotted paths into the resolved config)
COSMETIC_KEYS = ("progress", "run_dir", "out_dir", "out", "logger", "save_rollouts", "save_frames", "exp_name",
                 "resume", "rerun", "log_every")
#: prepared artefacts whose content a run depends on (relative to the scene folder)
SCENE_ARTEFACTS = ("navmesh.npz", "3dgs.ply", "episodes.json", "collision_mesh.ply")


class RunIdentityError(RuntimeError):
    """A run folder holds the results of another configuration or scene."""


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def artefact_digest(path: Path) -> str:
    """What a run depends on in a prepared artefact: its bytes, except `navmesh.npz`, whose stored
    `content_hash` (planners.NavMesh.content_hash: settings and arrays) is used. Its bytes also hold the
    bake time and the zip's write timestamps, so a rebake of identical geometry would otherwise change
    the identity. Files without the field (older bakes, not a navmesh) fall back to the bytes."""
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                content = json.loads(str(z["meta"])).get("content_hash") if "meta" in z.files else None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            content = None
        if content:
            return f"navmesh-content:{content}"
    return file_sha256(path)


def scene_identity(root, episodes_path=None, files: dict | None = None) -> dict:
    """`{"path", "artefacts": {file: sha256}}` of the scene: its prepared artefacts (default) or `files`
    (name -> path), plus the episodes file the run uses."""
    root = Path(root).resolve()
    files = dict(files) if files is not None else {name: root / name for name in SCENE_ARTEFACTS}
    if episodes_path is not None:
        files["episodes.json"] = Path(episodes_path).resolve()
    return {"path": str(root), "artefacts": {n: artefact_digest(Path(p)) for n, p in sorted(files.items())
                                             if Path(p).is_file()},
            "episodes_path": str(episodes_path) if episodes_path is not None else None}


def identity_config(config: dict) -> dict:
    """The resolved config without the cosmetic keys, and without `env.pedestrians` while it is null or its count 0: off,
    the block changes nothing, so runs made before it existed keep their identity."""
    out = {k: v for k, v in config.items() if k not in COSMETIC_KEYS}
    env = out.get("env")
    if isinstance(env, dict) and "pedestrians" in env and not (env["pedestrians"] or {}).get("count"):
        out["env"] = {k: v for k, v in env.items() if k != "pedestrians"}
    return out


def run_identity(config: dict, scene: dict) -> dict:
    """`{"hash", "config", "scene"}`; `hash` (16 hex) covers both."""
    cfg = identity_config(config)
    return {"hash": _digest({"config": cfg, "scene": scene})[:16], "config": cfg, "scene": scene}


def flatten_dotted(d, prefix="") -> dict:
    """Nested dicts -> one level of dotted keys (`{"a": {"b": 1}}` -> `{"a.b": 1}`), to diff configs key by key."""
    if not isinstance(d, dict):
        return {prefix.rstrip("."): d}
    out = {}
    for k, v in d.items():
        out.update(flatten_dotted(v, f"{prefix}{k}."))
    return out


def dotted_diff(old: dict, new: dict, skip: tuple[str, ...] = ()) -> list[str]:
    """`key: old -> new` for every dotted key whose value differs between two nested dicts, sorted; keys
    starting with a prefix in `skip` are left out."""
    a, b = flatten_dotted(old), flatten_dotted(new)
    return [f"{k}: {a.get(k, '<absent>')!r} -> {b.get(k, '<absent>')!r}" for k in sorted(set(a) | set(b))
            if a.get(k) != b.get(k) and not (skip and k.startswith(skip))]


def identity_diff(old: dict, new: dict, limit: int = 8) -> list[str]:
    """Human-readable differences `key: old -> new` between two identities."""
    diffs = dotted_diff(*({"config": x.get("config", {}), "scene": x.get("scene", {})} for x in (old, new)))
    return diffs[:limit] + ([f"... and {len(diffs) - limit} more"] if len(diffs) > limit else [])


def check_resume(stored: dict | None, current: dict, where: Path, fresh_hint: str) -> None:
    """Refuse to continue a run made by another identity (`stored` None: an old run without one)."""
    if stored is None:
        raise RunIdentityError(f"{where}: holds a run without a recorded identity (made by an older version); "
                               f"{fresh_hint}")
    if stored.get("hash") != current["hash"]:
        lines = "\n  ".join(identity_diff(stored, current))
        raise RunIdentityError(f"{where}: holds run {stored.get('hash')}, this is run {current['hash']}; "
                               f"they differ in:\n  {lines}\n{fresh_hint}")
