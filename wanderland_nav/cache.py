"""Hash-and-skip caching: a digest of everything that determines an artefact, stored beside it; the one
user cache folder (`cache_root`) every cache that cannot live beside its source uses; and the ledger of the
resumable stores (`Ledger`: the grounding study's cells, the benchmark's evaluations).

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

from wanderland_nav.atomic import atomic_write_json

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


class Ledger:
    """The resumable stores' one ledger: a JSON file of key -> {hash, status (done | failed | blocked | running),
    ...what the job records}, rewritten atomically after every job, so a killed run loses at most the job it was
    running. The grounding study keeps its cells in `<out>/done.json` (with dir, seconds, info | error), the
    benchmark its evaluations in `<out>/runs/done.json` (with the file holding the records).

    A key is one job; its hash says which inputs made it. When a key runs again with another hash (two study
    configs on one `out`, e.g. `grounding` and `grounding_recipe`, whose BC+RL evaluations share keys), the
    earlier DONE entry moves under `earlier[<its hash>]` and still counts for that hash, so alternating the
    configs re-runs nothing; what it made (a folder or file named by hash) is never touched.

    Several processes may share one ledger (e.g. one study process per seed on a multi-core box): `record` merges
    into the file as it is now under an exclusive lock, and `status` re-reads it, so one process sees the jobs
    another finished; a job another live process is running (`running` with its pid) is skipped. Two processes
    can therefore work through the same plan, e.g. one in reverse preset order."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.entries: dict[str, dict] = self._read()

    def _read(self) -> dict[str, dict]:
        if not self.path.is_file():
            return {}
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError) as e:  # truncated or emptied: its jobs are redone, never a crash that sticks
            log.warning("%s: unreadable ledger (%s); its jobs are redone and the ledger replaced", self.path, e)
            return {}

    def entry(self, key: str, digest: str) -> dict | None:
        """The entry `key` has for `digest` (current or earlier), as of the last `status` / `record`."""
        e = self.entries.get(key)
        if e is None or e.get("hash") == digest:
            return e
        return e.get("earlier", {}).get(digest)

    def status(self, key: str, digest: str) -> str | None:
        self.entries = self._read() or self.entries
        e = self.entry(key, digest)
        return None if e is None else e["status"]

    def record(self, key: str, entry: dict, *, unless_taken: bool = False) -> bool:
        """Write `entry` for `key`; with `unless_taken`, only when no other live process has claimed or
        finished the job with the same hash meanwhile (check and write under one lock). -> written."""
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            now = self._read()
            old = now.get(key, {})
            if unless_taken and old.get("hash") == entry.get("hash") and (
                    old.get("status") == "done" or (old.get("status") == "running" and process_alive(old.get("pid")))):
                self.entries = now
                return False
            earlier = dict(old.get("earlier", {}))
            if old.get("status") == "done" and old.get("hash") != entry.get("hash"):
                earlier[old["hash"]] = {k: v for k, v in old.items() if k != "earlier"}
            earlier.pop(entry.get("hash"), None)  # the entry itself is now the current one for its hash
            self.entries = {**now, key: {**entry, **({"earlier": earlier} if earlier else {})}}
            atomic_write_json(self.path, self.entries)
            return True


def process_alive(pid) -> bool:
    """Whether process `pid` (another process working on a job of the ledger) still runs on this machine."""
    if not pid or pid == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
