"""Write-to-temp-then-rename, so a crash never leaves a half-written artefact behind.

Every file the framework produces (scenes, meshes, navmeshes, episodes, checkpoints,
rollouts) goes through `atomic_path`: the writer gets a temporary path in the same folder
and the result is renamed over the target only once the writer returned without error.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `target`; rename it onto `target` on success.

    The temporary name keeps the target's suffix so libraries that pick a format from the
    extension (trimesh, PIL, numpy) still work.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp makes 0600 files; give the artefact the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        if tmp_path.exists():
            os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def atomic_write_bytes(target: str | os.PathLike, data: bytes) -> None:
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(target: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(target, text.encode("utf-8"))


def atomic_write_json(target: str | os.PathLike, obj, *, indent: int | None = 2) -> None:
    """Deterministic JSON (sorted keys are NOT forced: field order is part of the schema)."""
    atomic_write_text(target, json.dumps(obj, indent=indent, allow_nan=False) + "\n")
