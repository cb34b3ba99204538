"""One prediction against one ground truth, or a folder of predictions against a folder of scenes.

`evaluate_poses` matches cameras, aligns (SE(3) and Sim(3) Umeyama on the matched centres),
and returns every metric of `metrics.py` with the matching summary (completeness). R-ATE is one
number: Umeyama's rotation does not depend on whether the scale is estimated, so the SE(3) and
Sim(3) alignments rotate the prediction identically. The pair metrics use the Sim(3)-scaled
prediction (only the scale matters to them).

`evaluate_folders` gives the paper's table over several scenes: per-scene rows, mean and median
over the scenes that were evaluated, and SR = share of ground-truth scenes with AUC@30 > 0.1,
where a scene without a prediction, or whose inputs are degenerate, counts as a failure (listed
with the reason, never dropped).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wanderland_nav.recon import metrics as M
from wanderland_nav.recon.align import umeyama
from wanderland_nav.recon.associate import match
from wanderland_nav.recon.poses import PoseSet, ReconInputError
from wanderland_nav.recon.readers import detect_kind, read_poses

SR_AUC_THRESHOLD = 0.1
PREDICTION_SUFFIXES = (".txt", ".json", ".tum")  # files that can be one scene's input in a folder of scenes
TABLE_COLUMNS = (  # (key, header, format): the paper's Table 2 columns
    ("t_ate_se3", "T-ATE^R (m)", "{:.4f}"), ("t_ate_sim3", "T-ATE^S (m)", "{:.4f}"), ("r_ate_deg", "R-ATE (deg)", "{:.3f}"),
    ("t_rte_m", "T-RTE (m)", "{:.4f}"), ("t_rte_deg", "T-RTE (deg)", "{:.3f}"), ("r_rte_deg", "R-RTE (deg)", "{:.3f}"),
    ("auc30", "AUC@30", "{:.4f}"), ("completeness", "complete", "{:.3f}"),
)


@dataclass
class PoseResult:
    """Metrics of one scene, and the matched, aligned centres the plots draw."""

    name: str
    metrics: dict
    gt_centers: np.ndarray  # [M,3] ground-truth centres of the matched cameras
    pred_centers_sim3: np.ndarray  # [M,3] Sim(3)-aligned predicted centres
    pred_centers_se3: np.ndarray  # [M,3] SE(3)-aligned predicted centres
    up_axis: str | None = None  # ground truth's up axis when known (plots look down it)


def evaluate_poses(pred: PoseSet, gt: PoseSet, *, name: str = "", max_time_diff: float = 0.01,
                   time_offset: float = 0.0, rpe_delta: int = 1, collinear_tol: float = 1e-9,
                   chunk_pairs: int = 1 << 16, device: str = "cpu") -> PoseResult:
    """Every pose metric of `pred` against `gt` (see module docstring); ReconInputError on degenerate input."""
    m = match(pred, gt, max_diff=max_time_diff, offset=time_offset)
    what = f"{pred.source} vs {gt.source}"
    if len(m) < 3:
        raise ReconInputError(f"{what}: only {len(m)} of {len(gt)} ground-truth cameras have a predicted pose "
                              f"(matched by {m.by}); alignment needs at least 3")
    P, G = pred.world_from_cam[m.pred_idx], gt.world_from_cam[m.gt_idx]
    se3 = umeyama(P[:, :3, 3], G[:, :3, 3], with_scale=False, collinear_tol=collinear_tol, what=what)
    sim3 = umeyama(P[:, :3, 3], G[:, :3, 3], with_scale=True, collinear_tol=collinear_tol, what=what)
    P_se3, P_sim3 = se3.apply_to_poses(P), sim3.apply_to_poses(P)
    ape_se3, ape_sim3 = M.ape(G, P_se3), M.ape(G, P_sim3)
    out = {**m.summary(), "duplicates_dropped": {"pred": pred.duplicates_dropped, "gt": gt.duplicates_dropped},
           "t_ate_se3": ape_se3["trans_m"]["rmse"], "t_ate_sim3": ape_sim3["trans_m"]["rmse"],
           "r_ate_deg": ape_sim3["rot_deg"]["rmse"], "sim3_scale": sim3.s,
           **M.all_pairs(G, P_sim3, chunk_pairs=chunk_pairs, device=device),
           "ape": {"se3": ape_se3, "sim3": ape_sim3},
           "rpe": {"se3": M.rpe(G, P_se3, rpe_delta), "sim3": M.rpe(G, P_sim3, rpe_delta)}}
    return PoseResult(name or Path(gt.source).name, out, G[:, :3, 3], P_sim3[:, :3, 3], P_se3[:, :3, 3], gt.up_axis)


@dataclass
class Benchmark:
    """Per-scene results, scenes that failed (name -> reason), and the aggregate rows."""

    results: list[PoseResult]
    failed: dict[str, str] = field(default_factory=dict)

    @property
    def n_scenes(self) -> int:
        return len(self.results) + len(self.failed)

    def aggregate(self) -> dict:
        """{"mean": {...}, "median": {...}, "sr": share of all scenes with AUC@30 > 0.1, "scenes": counts}."""
        keys = [k for k, _, _ in TABLE_COLUMNS] + ["sim3_scale"]
        vals = {k: np.array([r.metrics[k] for r in self.results], dtype=np.float64) for k in keys}
        ok = sum(r.metrics["auc30"] > SR_AUC_THRESHOLD for r in self.results)
        return {"mean": {k: float(np.nanmean(v)) if np.isfinite(v).any() else math.nan for k, v in vals.items()},
                "median": {k: float(np.nanmedian(v)) if np.isfinite(v).any() else math.nan for k, v in vals.items()},
                "sr": ok / self.n_scenes if self.n_scenes else math.nan,
                "scenes": {"evaluated": len(self.results), "failed": len(self.failed), "total": self.n_scenes}}

    def table(self, label: str = "") -> str:
        """Markdown table like the paper's Table 2: a row per scene, then mean / median, then SR."""
        head = "| scene | " + " | ".join(h for _, h, _ in TABLE_COLUMNS) + " |"
        lines = [head, "|---|" + "---|" * len(TABLE_COLUMNS)]

        def row(name: str, d: dict) -> str:
            return f"| {name} | " + " | ".join(fmt.format(d.get(k, math.nan)) for k, _, fmt in TABLE_COLUMNS) + " |"

        lines += [row(r.name, r.metrics) for r in self.results]
        lines += [f"| {n} | failed: {why.splitlines()[0][:160]} |" for n, why in self.failed.items()]
        if self.n_scenes > 1:
            agg = self.aggregate()
            lines += [row("**mean**", agg["mean"]), row("**median**", agg["median"])]
        agg = self.aggregate()
        lines.append("")
        lines.append(f"{label + ': ' if label else ''}SR (AUC@30 > {SR_AUC_THRESHOLD}) = {agg['sr']:.3f} over "
                     f"{self.n_scenes} scene(s) ({len(self.failed)} failed or without prediction). "
                     "ATE after Umeyama SE(3) (^R) / Sim(3) (^S); R-ATE and pair metrics on the Sim(3)-aligned prediction.")
        return "\n".join(lines)


def is_scene_collection(path) -> bool:
    """True for a folder that is not itself one input but holds inputs (one per scene)."""
    p = Path(path)
    if not p.is_dir():
        return False
    try:
        detect_kind(p)
        return False
    except ReconInputError:
        return True


def find_prediction(pred_root: Path, scene: str) -> Path | None:
    """`<pred_root>/<scene>` (folder or file), else `<pred_root>/<scene>.{txt,json,tum}`."""
    for cand in (pred_root / scene, *(pred_root / f"{scene}{ext}" for ext in PREDICTION_SUFFIXES)):
        if cand.exists():
            return cand
    return None


def evaluate_paths(pred, gt, **kwargs) -> Benchmark:
    """One input against one input, or (both folders of scenes) every ground-truth scene in turn: each
    sub-folder of `gt`, and each `.txt`/`.json`/`.tum` file in it (other files, e.g. a README, are not scenes)."""
    pred, gt = Path(pred), Path(gt)
    if not is_scene_collection(gt):
        return Benchmark([evaluate_poses(read_poses(pred), read_poses(gt), **kwargs)])
    if not pred.is_dir():
        raise ReconInputError(f"gt={gt} is a folder of scenes, so pred must be a folder of predictions, got {pred}")
    scenes = sorted(d.name for d in gt.iterdir() if not d.name.startswith(".")
                    and (d.is_dir() or d.suffix in PREDICTION_SUFFIXES))
    if not scenes:
        raise ReconInputError(f"gt={gt}: empty folder")
    results, failed = [], {}
    for name in scenes:  # one iteration per scene (tens); each scene's metrics are batched
        p = find_prediction(pred, Path(name).stem if (gt / name).is_file() else name)
        if p is None:
            failed[name] = f"no prediction in {pred}"
            continue
        try:
            results.append(evaluate_poses(read_poses(p), read_poses(gt / name), name=name, **kwargs))
        except ReconInputError as e:
            failed[name] = str(e)
    return Benchmark(results, failed)
