"""Write-to-temp-then-rename, so a crash never leaves a half-written artefact behind.

Every file the framework produces (scenes, meshes, navmeshes, episodes, checkpoints,
rollouts) goes through `atomic_path`: the writer gets a temporary path in the same folder
and the result is renamed over the target only once the writer returned without error.

Durability: the temporary file is `fsync`ed before the rename and the folder after it, so a
power cut right after a save leaves either the old file or the complete new one, never a
renamed-but-empty file (ext4/xfs may otherwise commit the rename before the data). A writer
that fails part-way leaves the old file untouched and no temporary behind; a full disk is reported
as `OSError` ENOSPC naming the file being written, also when the writer's own error does not say so
(torch's "unexpected pos"). A writer killed outright (kill -9) leaves its temporary: temporaries carry
host and process id, and the next write of the same target removes those whose process is gone.
"""

from __future__ import annotations

import contextlib
import json
import math
import errno
import os
import shutil
import socket
import tempfile
import time
from glob import escape as glob_escape
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
    remove_stale_temps(target.parent, target.stem)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.{_owner()}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        try:
            yield tmp_path
            # mkstemp makes 0600 files; give the artefact the permissions a plain open() would.
            if tmp_path.exists():
                os.chmod(tmp_path, 0o666 & ~_umask())
                _fsync_path(tmp_path, os.O_RDONLY)
            os.replace(tmp_path, target)
            _fsync_path(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        except Exception as e:
            _raise_if_disk_full(e, target)
            raise
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _owner() -> str:
    """`<host>-<pid>` of the writing process (computed per call: forked workers have their own pid)."""
    return f"{socket.gethostname().replace('.', '_').replace('-', '_')}-{os.getpid()}"



_FULL_BYTES = 1 << 20  # below this much free space a failed write is taken for a full disk


def _raise_if_disk_full(e: BaseException, target: Path) -> None:
    """ENOSPC / EDQUOT, or any writer error while the disk is (nearly) full -> OSError ENOSPC naming `target`."""
    code = getattr(e, "errno", None)
    try:
        free = shutil.disk_usage(target.parent).free
    except OSError:
        free = None
    if code in (errno.ENOSPC, errno.EDQUOT) or (free is not None and free < _FULL_BYTES):
        raise OSError(errno.ENOSPC, f"No space left on device while writing {target} ({free} bytes free; "
                                    f"the previous version, if any, is intact): {e}", str(target)) from e


def remove_stale_temps(folder: str | os.PathLike, base: str, *, foreign_age_s: float = 86400.0) -> list[Path]:
    """Delete the temporaries `.<base>.<host>-<pid>.*.tmp*` (files and folders) in `folder` that earlier,
    killed writers left: those of a process on this host that no longer runs, and any older than
    `foreign_age_s` (another host's, or of an unknown owner)."""
    host = _owner().rsplit("-", 1)[0]
    removed = []
    for p in Path(folder).glob(f".{glob_escape(base)}.*.tmp*"):
        h, _, pid = p.name[len(base) + 2:].split(".")[0].rpartition("-")
        mine = h == host and pid.isdigit()
        try:
            stale = (not _alive(int(pid))) if mine else time.time() - p.lstat().st_mtime > foreign_age_s
        except OSError:
            continue
        if stale:
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
            removed.append(p)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


@contextlib.contextmanager
def atomic_dir(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty temporary folder beside `target`; on success it replaces `target` as a whole.

    For a set of files that belong together (the goal views of one episodes file): a reader sees the
    old set or the complete new one, never a mix, and a killed writer leaves only a hidden temporary.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(target.parent, target.name)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.{_owner()}.", suffix=".tmpdir", dir=target.parent))
    old = None
    try:
        yield tmp
        for f in tmp.rglob("*"):
            if f.is_file():
                _fsync_path(f, os.O_RDONLY)
        os.chmod(tmp, 0o777 & ~_umask())
        if target.exists():  # a folder cannot be renamed onto a non-empty one: move the old set aside first
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.{_owner()}.", suffix=".old.tmpdir", dir=target.parent))
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
