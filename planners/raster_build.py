"""Batched build of `GeodesicRaster` sources: the goal-independent work once per navmesh, then all goals at once.

The source of a sample point p for goal g is the goal itself if p sees it, else the corner a that
minimises `|p a| + d(a, g)` over the corners p sees that a path can bend around (tangent ones). The
expensive part, which corners each sample sees, does not depend on the goal. The first build per
goal (`GeodesicField.query_local`, ~0.3-0.6 CPU-s per goal on the demo) redid it for every goal;
here it is done once per navmesh (`visible_pairs`: a CSR list of (sample, corner, |p a|)), and a goal
then costs one visibility test per sample (does p see the goal) plus a segment minimum over the
pairs (`simple_sources`). Same candidates, same tests, same minimum as `query_local`, so the same
sources (up to exact ties between two corners, where both give the same distance).

Goals on islands with overlapping levels (no visibility fans) keep the per-goal exact query.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_ROWS_PER_CHUNK = 512  # samples per tangency block: [512, 3S] float64 (S corners of one island)
_PAIR_BUDGET = 1 << 22  # (goal, pair) values per segment-minimum block (~32 MB float64)


@dataclass
class VisiblePairs:
    """Per sample, the corners it sees that a shortest path can bend around (goal-independent).

    start `[P+1]` int64 CSR offsets; corner `[nnz]` int32 (corner id < M); dist `[nnz]` float64 |p a| (m);
    island `[P]` int64: the sample's island where its triangle and its column agree, else -1 (such
    samples get no source, as `query_local` answers inf there)."""

    start: np.ndarray
    corner: np.ndarray
    dist: np.ndarray
    island: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        return {"start": self.start, "corner": self.corner, "dist": self.dist, "island": self.island}


def visible_pairs(field, samples: np.ndarray, sample_tri_island: np.ndarray) -> VisiblePairs:
    """The visible tangent corners of every sample (local frame samples[P,3]), corners of its own island only."""
    P = samples.shape[0]
    island = field._island_np(samples)
    island = np.where(island == sample_tri_island, island, -1)
    node_island = field.nm.node_island
    rows_out, corner_out = [], []
    for isl in np.unique(island[island >= 0]):  # per island (a handful): its own corners only
        rows = np.flatnonzero(island == isl)
        cand = np.flatnonzero(node_island == isl)
        if cand.shape[0] == 0:
            continue
        for j in range(0, rows.shape[0], _ROWS_PER_CHUNK):
            r = rows[j:j + _ROWS_PER_CHUNK]
            qx, qy = samples[r, 0], samples[r, 1]
            ri, ci = np.nonzero(np.isfinite(field.bend_distances(qx, qy, cand)))  # `query_local`'s candidates
            seen = field._sees(cand[ci], qx[ri], qy[ri])
            rows_out.append(r[ri[seen]])
            corner_out.append(cand[ci[seen]])
    row = np.concatenate(rows_out) if rows_out else np.zeros(0, np.int64)
    corner = np.concatenate(corner_out) if corner_out else np.zeros(0, np.int64)
    order = np.argsort(row, kind="stable")
    row, corner = row[order], corner[order]
    a = field.nm.node_xy
    dist = np.hypot(samples[row, 0] - a[corner, 0], samples[row, 1] - a[corner, 1])
    start = np.searchsorted(row, np.arange(P + 1)).astype(np.int64)
    return VisiblePairs(start, corner.astype(np.int32), dist, island.astype(np.int64))


def simple_sources(field, pairs: VisiblePairs, samples: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """`[len(goals), P]` int32 sources of every sample for goals (indices into the field, all on
    single-level islands): M where the sample sees the goal, else its best corner, -1 where none
    (other island, or no visible corner leads to the goal)."""
    n = field._np
    M, P = n["M"], samples.shape[0]
    out = np.full((goals.shape[0], P), -1, dtype=np.int32)
    step = max(1, _PAIR_BUDGET // max(P, 1))
    for j in range(0, goals.shape[0], step):  # goal blocks bound the [g, P] work arrays
        gb = goals[j:j + step]
        via = _best_corners(n["c2g"], pairs, gb)  # [g, P], -1 where no corner
        g, p = np.nonzero(pairs.island[None, :] == n["goal_island"][gb][:, None])  # samples on the goal's island
        direct = field._sees(M + gb[g], samples[p, 0], samples[p, 1])  # |p g| <= any path via a corner
        out[j + g, p] = np.where(direct, M, via[g, p])
    return out


def _best_corners(c2g: np.ndarray, pairs: VisiblePairs, goals: np.ndarray) -> np.ndarray:
    """`[len(goals), P]` argmin over each sample's pairs of `|p a| + c2g[g, a]` as a corner id (-1: none
    finite). Goals in blocks of `_PAIR_BUDGET` values; within a block one segment minimum per sample."""
    P = pairs.start.shape[0] - 1
    out = np.full((goals.shape[0], P), -1, dtype=np.int32)
    nnz = pairs.corner.shape[0]
    if nnz == 0:
        return out
    counts = np.diff(pairs.start)
    busy = np.flatnonzero(counts > 0)
    seg = pairs.start[busy]
    seg_of_pair = np.repeat(np.arange(busy.shape[0]), counts[busy])
    step = max(1, _PAIR_BUDGET // nnz)
    for j in range(0, goals.shape[0], step):
        val = pairs.dist[None, :] + c2g[goals[j:j + step]][:, pairs.corner]  # [g, nnz]
        best = np.minimum.reduceat(val, seg, axis=1)  # [g, busy]
        first = np.where(val == best[:, seg_of_pair], np.arange(nnz)[None, :], nnz)
        idx = np.minimum.reduceat(first, seg, axis=1)
        out[j:j + step, busy] = np.where(np.isfinite(best), pairs.corner[np.minimum(idx, nnz - 1)], -1)
    return out
