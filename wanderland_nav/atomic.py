"""Write-to-temp-then-rename, so a crash never leaves a half-written artefact behind.

Every file the framework produces (scenes, meshes, navmeshes, episodes, checkpoints,
rollouts) goes through `atomic_path`: the writer gets a temporary path in the same folder
and the result is renamed over the target only once the writer returned without error.

Durability: the temporary file is `fsync`ed before the rename and the folder after it, so a
power cut right after a save leaves either the old file or the complete new one, never a
renamed-but-empty file (ext4/xfs may otherwise commit the rename before the data). A writer
that fails part-way (a full disk raises `OSError: [Errno 28] No space left on device`) leaves
the old file untouched and no temporary behind.
"""

from __future__ import annotations

import contextlib
import json
import math
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
        if tmp_path.exists():
            os.chmod(tmp_path, 0o666 & ~_umask())
            _fsync_path(tmp_path, os.O_RDONLY)
        os.replace(tmp_path, target)
        _fsync_path(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


@contextlib.contextmanager
def atomic_dir(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty temporary folder beside `target`; on success it replaces `target` as a whole.

    For a set of files that belong together (the goal views of one episodes file): a reader sees the
    old set or the complete new one, never a mix, and a killed writer leaves only a hidden temporary.
    """
    import shutil

    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmpdir", dir=target.parent))
    old = None
    try:
        yield tmp
        for f in tmp.rglob("*"):
            if f.is_file():
                _fsync_path(f, os.O_RDONLY)
        os.chmod(tmp, 0o777 & ~_umask())
        if target.exists():  # a folder cannot be renamed onto a non-empty one: move the old set aside first
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old.tmpdir", dir=target.parent))
            os.replace(target, old / "x")
        os.replace(tmp, target)
        _fsync_path(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    finally:
        for d in (tmp, old):
            if d is not None and d.exists():
                shutil.rmtree(d, ignore_errors=True)


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _fsync_path(path: Path, flags: int) -> None:
    """Flush a file's data, or a folder's entries, to disk. Folders cannot be opened on Windows: skipped there."""
    try:
        fd = os.open(path, flags)
    except (IsADirectoryError, PermissionError):
        if os.name == "nt":
            return
        raise
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_bytes(target: str | os.PathLike, data: bytes) -> None:
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(target: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(target, text.encode("utf-8"))


def atomic_write_json(target: str | os.PathLike, obj, *, indent: int | None = 2) -> None:
    """Deterministic JSON (sorted keys are NOT forced: field order is part of the schema)."""
    atomic_write_text(target, json.dumps(obj, indent=indent, allow_nan=False) + "\n")


def finite_or_none(obj):
    """`obj` with every non-finite float (NaN, inf) replaced by None, recursively through dicts and
    lists: JSON has no NaN, and an undefined number must never be read back as a value."""
    if isinstance(obj, dict):
        return {k: finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_none(v) for v in obj]
    return None if isinstance(obj, float) and not math.isfinite(obj) else obj
