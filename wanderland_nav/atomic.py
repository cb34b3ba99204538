"""Write-to-temp-then-rename, so a crash never leaves a half-written artefact behind.

Every file the framework produces (scenes, meshes, navmeshes, episodes, checkpoints,
rollouts) goes through `atomic_path`: the writer gets a temporary path in the same folder
and the result is renamed over the target only once the writer returned without error.
"""

from __future__ import annotations

import json
import os

from planners.atomic import atomic_path


def atomic_write_bytes(target: str | os.PathLike, data: bytes) -> None:
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(target: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(target, text.encode("utf-8"))


def atomic_write_json(target: str | os.PathLike, obj, *, indent: int | None = 2) -> None:
    """Deterministic JSON (sorted keys are NOT forced: field order is part of the schema)."""
    atomic_write_text(target, json.dumps(obj, indent=indent, allow_nan=False) + "\n")
