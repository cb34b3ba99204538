"""Raster sources kept per (navmesh content, goal): in memory for every env of a process, on disk beside the navmesh.

A training run builds its env twice (BC env, collector env) and every evaluation builds more, all
over the same navmesh and mostly the same goals; each used to rebuild every goal's raster. Here a
goal's sources are computed once per navmesh content and reused:

- key: `RASTER_VERSION`, `NavMesh.content_hash` (settings, cell size and every array: a rebaked or
  edited navmesh gets new keys, so a stale raster is never read) and the goal (its local xy and
  triangle, exact bytes);
- memory: one process-wide table, least recently used navmeshes dropped beyond `MEMORY_BUDGET`;
- disk (optional, `cache_dir`): `navmesh_raster_v<V>_<content hash>/goal_<key>.npy` (one int32 row per goal,
  written once, atomically) and `pairs.npz` (the goal-independent visible pairs); the `navmesh` prefix
  keeps it out of what scene copies and source hashes take from a scene folder (`degrade.build`). A file that is
  unreadable or of the wrong size is rebuilt and overwritten; a folder that cannot be written is
  reported once (`warnings.warn`) and the cache goes on in memory.
"""

from __future__ import annotations

import hashlib
import logging
import warnings
import zipfile
import zlib
from collections import OrderedDict
from pathlib import Path

import numpy as np

from planners.atomic import atomic_path
from planners.raster_build import VisiblePairs

RASTER_VERSION = 3  # bump when the sources a build produces change (v1: per-goal exact queries, no cache; v2: batched;
# v3: tangency margin `visibility.TANGENT_SLACK`)
MEMORY_BUDGET = 512 << 20  # bytes of cached rows + pairs over all navmeshes in this process

log = logging.getLogger(__name__)
#: what reading a damaged `.npy` / `.npz` raises (a truncated zip, a failed CRC, a bad header, a cut-off array)
UNREADABLE = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error)

_MEMORY: "OrderedDict[str, dict]" = OrderedDict()  # navmesh key -> {"pairs": VisiblePairs|None, "rows": {goal: row}}


def goal_key(goal_xy: np.ndarray, goal_tri: int) -> str:
    """16 hex of a goal's local xy (float64 bytes) and triangle."""
    tri = int(goal_tri).to_bytes(8, "little", signed=True)
    return hashlib.sha256(np.asarray(goal_xy, np.float64).tobytes() + tri).hexdigest()[:16]


def clear_memory() -> None:
    """Forget every cached raster of this process (tests, benchmarks of cold builds)."""
    _MEMORY.clear()


class RasterCache:
    """Cached sources of one navmesh (`n_samples` samples per goal). `stats`: where each goal came from."""

    def __init__(self, nm, n_samples: int, cache_dir: str | Path | None = None):
        self.key = f"v{RASTER_VERSION}_{nm.content_hash}"
        self.n_samples = int(n_samples)
        self.folder = Path(cache_dir) / f"navmesh_raster_{self.key}" if cache_dir is not None else None
        self.stats = {"memory_hits": 0, "disk_hits": 0, "built": 0}
        entry = _MEMORY.get(self.key)
        if entry is None:
            entry = _MEMORY[self.key] = {"pairs": None, "rows": {}}
        self._entry = entry

    def get(self, keys: list[str]) -> dict[str, np.ndarray]:
        """Rows `[P]` int32 of the goals found in memory or on disk (missing keys left out)."""
        if _MEMORY.get(self.key) is not self._entry:  # dropped by another navmesh's trim while this one is in use
            _MEMORY[self.key] = self._entry           # (many scenes in one process): held again, as the latest
        _MEMORY.move_to_end(self.key)
        rows = self._entry["rows"]
        out = {k: rows[k] for k in keys if k in rows}
        self.stats["memory_hits"] += len(out)
        for k in keys:
            if k not in out and self.folder is not None:
                row = self._read(self.folder / f"goal_{k}.npy")
                if row is not None and row.shape == (self.n_samples,) and row.dtype == np.int32:
                    out[k] = rows[k] = row
                    self.stats["disk_hits"] += 1
        self._trim()
        return out

    def put(self, keys: list[str], rows) -> None:
        """Store freshly built rows (`P` int32 each; views of the caller's raster are kept as they are,
        not copied) in memory and on disk."""
        self.stats["built"] += len(keys)
        self.share(keys, rows)
        for k in keys:
            self._write(f"goal_{k}.npy", lambda f, row=self._entry["rows"][k]: np.save(f, row))

    def share(self, keys: list[str], rows) -> None:
        """Keep `rows` (the caller's copies of rows it got from `get`, or built) as the memory rows of
        `keys`, so that a row read from disk or held for an older raster is not kept twice."""
        for k, row in zip(keys, rows):
            self._entry["rows"][k] = np.ascontiguousarray(row, dtype=np.int32)
        self._trim()

    def pairs(self, build) -> VisiblePairs:
        """The navmesh's visible pairs: memory, disk, or `build()` (then stored)."""
        if self._entry["pairs"] is None:
            pairs = self._read_pairs()
            if pairs is None:
                pairs = build()
                self._write("pairs.npz", lambda f: np.savez(f, **pairs.arrays()))
            self._entry["pairs"] = pairs
        return self._entry["pairs"]

    def _read_pairs(self) -> VisiblePairs | None:
        if self.folder is None or not (self.folder / "pairs.npz").is_file():
            return None
        path = self.folder / "pairs.npz"
        try:
            with np.load(path, allow_pickle=False) as z:
                pairs = VisiblePairs(**{k: z[k] for k in ("start", "corner", "dist", "island")})
        except UNREADABLE as e:  # truncated, empty, bit-flipped (a member's CRC) or foreign
            log.warning("%s: unreadable raster cache (%s: %s); rebuilding it", path, type(e).__name__, e)
            return None
        ok = (pairs.start.shape == (self.n_samples + 1,) and pairs.island.shape == (self.n_samples,)
              and pairs.corner.shape == pairs.dist.shape == (int(pairs.start[-1]),))
        if not ok:
            log.warning("%s: raster cache of other sizes than this navmesh's; rebuilding it", path)
        return pairs if ok else None

    @staticmethod
    def _read(path: Path) -> np.ndarray | None:
        if not path.is_file():
            return None
        try:
            return np.load(path, allow_pickle=False)
        except UNREADABLE as e:  # truncated or foreign: rebuilt and overwritten
            log.warning("%s: unreadable raster cache (%s: %s); rebuilding it", path, type(e).__name__, e)
            return None

    def _write(self, name: str, save) -> None:
        if self.folder is None:
            return
        try:
            with atomic_path(self.folder / name) as tmp:
                with open(tmp, "wb") as f:
                    save(f)
        except OSError as e:
            warnings.warn(f"{self.folder}: raster cache not writable ({e}); keeping rasters in memory only",
                          stacklevel=3)
            self.folder = None

    def _trim(self) -> None:
        """Drop the least recently used navmeshes' entries beyond `MEMORY_BUDGET` (never the current one)."""
        def size(e):  # rows that are views of a raster's [G, P] matrix keep all of it alive: count it once
            p = e["pairs"]
            owners = [r if r.base is None else r.base for r in e["rows"].values()]
            rows = sum({id(o): o.nbytes for o in owners}.values())
            return rows + (sum(a.nbytes for a in p.arrays().values()) if p else 0)
        total = sum(size(e) for e in _MEMORY.values())
        while total > MEMORY_BUDGET and len(_MEMORY) > 1 and next(iter(_MEMORY)) != self.key:
            total -= size(_MEMORY.popitem(last=False)[1])
