"""Hash-and-skip caching: a digest of everything that determines an artefact, stored beside it; and the one
user cache folder (`cache_root`) every cache that cannot live beside its source uses.

Scene preparation (collision mesh, navmesh sidecars), the demo scene (its marker file) and episode
generation (the episodes file's `generator` record) each rebuild only when the digest of their inputs
changed. They share the digest and the tolerant read of the stored record, so "same settings" means
the same thing everywhere: canonical JSON (sorted keys, `str()` for anything JSON cannot hold),
sha256, the first 16 hex digits.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import stat
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)


def file_sha256(path: str | os.PathLike, chunk: int = 1 << 22) -> str:
    """sha256 hex digest of a file's bytes, streamed (a splat or a point cloud can be gigabytes)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def json_digest(obj) -> str:
    """16 hex digits of sha256 over `obj` as canonical JSON (sorted keys; non-JSON values via `str`)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def read_record(path: str | os.PathLike) -> dict | None:
    """The JSON object stored at `path`, or None when it is missing, unreadable or not an object.

    A cache record that cannot be read means "rebuild", never an error: the artefact is rewritten
    together with a fresh record.
    """
    p = Path(path)
    if not p.is_file():
        return None
    try:
        obj = json.loads(p.read_text())
    except (OSError, ValueError) as e:  # truncated, emptied, not UTF-8 or not JSON
        log.warning("%s: unreadable record (%s: %s); treated as missing, what it describes is rebuilt and the "
                    "record replaced", p, type(e).__name__, e)
        return None
    if not isinstance(obj, dict):
        log.warning("%s: not a JSON object; treated as missing, what it describes is rebuilt and the record replaced", p)
        return None
    return obj


def writable(folder: Path) -> bool:
    """Whether the project may create files in `folder`: a folder without any write bit is read-only by its
    owner's intent, even for root (who could write there anyway: a copy of shared data laid out read-only, say);
    otherwise tried, not guessed (permissions, read-only mounts, ACLs)."""
    try:
        if not os.stat(folder).st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
            return False
        fd, probe = tempfile.mkstemp(prefix=".write_probe.", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


CACHE_ENV = "WANDERLAND_NAV_CACHE"
OLD_CACHE_ENV = "WANDERLAND_CACHE"  # the splat hierarchy's variable once; still read, with a warning


def cache_root() -> Path:
    """`$WANDERLAND_NAV_CACHE`, else `$XDG_CACHE_HOME/wanderland_nav`, else `~/.cache/wanderland_nav`: the one
    user cache folder (products of read-only scenes, splat hierarchies of read-only folders).

    `$WANDERLAND_CACHE` (the hierarchy cache's variable once) is still read when `$WANDERLAND_NAV_CACHE` is unset,
    with a deprecation warning; set beside it with another value, it is ignored, and that is said too."""
    new, old = os.environ.get(CACHE_ENV), os.environ.get(OLD_CACHE_ENV)
    if old and not new:
        log.warning("$%s is deprecated: set $%s instead (using %s for every cache)", OLD_CACHE_ENV, CACHE_ENV, old)
        new = old
    elif old and Path(old).expanduser() != Path(new).expanduser():
        log.warning("$%s=%s is ignored: $%s=%s is the cache folder", OLD_CACHE_ENV, old, CACHE_ENV, new)
    if new:
        return Path(new).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "wanderland_nav"

