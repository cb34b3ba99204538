"""Match predicted cameras to ground-truth cameras: by image name, or by timestamp for TUM files.

Unmatched cameras are never dropped silently: `Matches` keeps both totals, and the benchmark
reports `completeness = matched / ground-truth cameras` beside every metric.

Timestamps follow evo's `associate_trajectories` (and so the TUM tools' common use): every stamp
of the *shorter* trajectory takes its nearest stamp in the longer one, kept when
`|t_short - (t_long + offset)| <= max_diff` (10 ms by default). Like evo, two stamps of the shorter
trajectory may take the same nearest stamp; `Matches.shared` counts how often that happened
(and the metrics then use that pose twice, as evo does).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePosixPath

import numpy as np

from wanderland_nav.recon.poses import PoseSet, ReconInputError


@dataclass(frozen=True)
class Matches:
    pred_idx: np.ndarray  # [M] int64 indices into the prediction
    gt_idx: np.ndarray  # [M] int64 indices into the ground truth, ascending
    n_pred: int
    n_gt: int
    by: str  # "name" | "stem" | "basename" | "timestamp"
    shared: int = 0  # extra uses of a longer-trajectory stamp already matched (timestamps only)

    def __len__(self) -> int:
        return int(self.gt_idx.shape[0])

    @property
    def completeness(self) -> float:
        """Share of ground-truth cameras with a predicted pose."""
        return len(np.unique(self.gt_idx)) / self.n_gt if self.n_gt else 0.0

    def summary(self) -> dict:
        return {"matched": len(self), "n_gt": self.n_gt, "n_pred": self.n_pred, "matched_by": self.by,
                "unmatched_gt": self.n_gt - len(np.unique(self.gt_idx)),
                "unmatched_pred": self.n_pred - len(np.unique(self.pred_idx)), "shared_matches": self.shared,
                "completeness": self.completeness}


def match(pred: PoseSet, gt: PoseSet, *, max_diff: float = 0.01, offset: float = 0.0) -> Matches:
    """Pair `pred` with `gt` by name (both named) or timestamp (both stamped); mixing is an error."""
    if pred.names is not None and gt.names is not None:
        return match_names(pred.names, gt.names)
    if pred.stamps is not None and gt.stamps is not None:
        return match_stamps(pred.stamps, gt.stamps, max_diff=max_diff, offset=offset)
    raise ReconInputError(f"cannot match {pred.source} ({pred.kind}, keyed by {'names' if pred.names else 'stamps'}) "
                          f"with {gt.source} ({gt.kind}, keyed by {'names' if gt.names else 'stamps'}): "
                          "a TUM trajectory can only be compared with another TUM trajectory")


_NAME_KEYS = (  # tried in order; the first that matches anything wins
    ("name", str),
    ("stem", lambda n: str(PurePosixPath(n).with_suffix(""))),  # 'left/0001.png' ~ 'left/0001.jpg'
    ("basename", lambda n: PurePosixPath(n).stem),  # 'left/0001.jpg' ~ '0001.png' (flat output folders)
)


def match_names(pred_names, gt_names) -> Matches:
    """Exact (normalised) image names; when none agree, names without extension, then bare file stems.
    A looser key is used only when it is unique among the ground-truth names (else it could pair wrongly)."""
    pairs: list[tuple[int, int]] = []
    by = "name"
    for by, key in _NAME_KEYS:
        gt_index: dict[str, int] = {}
        for i, n in enumerate(gt_names):
            gt_index.setdefault(key(n), i)
        if by != "name" and len(gt_index) < len(gt_names):
            continue  # ambiguous in the ground truth (e.g. left/0001 and right/0001)
        pairs = [(i, gt_index[key(n)]) for i, n in enumerate(pred_names) if key(n) in gt_index]
        if pairs:
            break
    pairs.sort(key=lambda ij: ij[1])
    p = np.array([i for i, _ in pairs], dtype=np.int64)
    g = np.array([j for _, j in pairs], dtype=np.int64)
    return Matches(p, g, len(pred_names), len(gt_names), by)


def match_stamps(pred_stamps, gt_stamps, *, max_diff: float = 0.01, offset: float = 0.0) -> Matches:
    """evo-style nearest-stamp association (see module docstring); `offset` is added to the prediction's stamps."""
    if max_diff < 0:
        raise ValueError(f"max_time_diff must be >= 0, got {max_diff}")
    tp = np.asarray(pred_stamps, dtype=np.float64) + offset
    tg = np.asarray(gt_stamps, dtype=np.float64)
    if len(tp) == 0 or len(tg) == 0:
        empty = np.zeros(0, np.int64)
        return Matches(empty, empty, len(tp), len(tg), "timestamp")
    pred_short = len(tp) < len(tg)
    short, long_ = (tp, tg) if pred_short else (tg, tp)
    order = np.argsort(long_, kind="stable")
    sl = long_[order]
    pos = np.clip(np.searchsorted(sl, short), 1, len(sl) - 1) if len(sl) > 1 else np.zeros(len(short), np.int64)
    left, right = pos - 1 if len(sl) > 1 else pos, pos
    take_right = np.abs(sl[right] - short) < np.abs(sl[left] - short)  # ties go to the earlier stamp, like argmin
    near = np.where(take_right, right, left)
    ok = np.abs(sl[near] - short) <= max_diff
    i_short, i_long = np.flatnonzero(ok), order[near[ok]]
    p, g = (i_short, i_long) if pred_short else (i_long, i_short)
    srt = np.lexsort((p, g))
    shared = int(len(i_long) - len(np.unique(i_long)))
    return Matches(p[srt].astype(np.int64), g[srt].astype(np.int64), len(tp), len(tg), "timestamp", shared)
