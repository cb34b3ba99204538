"""Write a rerun recording (`.rrd`) of reconstruction benchmark results: GT vs aligned prediction per scene.

Entities, one subtree per scene, all static, in the ground-truth frame:
`recon/<scene>/{gt, pred_sim3, pred_se3}` (line strip + camera centres) and `recon/<scene>/error`
(a segment from every ground-truth centre to its aligned prediction, coloured by its length).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from wanderland_nav.atomic import atomic_path
from wanderland_nav.viz.rerun_episodes import entity_name

_COLORS = {"gt": [40, 200, 60], "pred_sim3": [230, 50, 50], "pred_se3": [60, 120, 230]}


def _error_colors(err: np.ndarray) -> np.ndarray:
    """`[M]` errors -> `[M,3]` uint8, yellow (0) to red (the largest)."""
    a = err / err.max() if err.size and err.max() > 0 else np.zeros_like(err)
    return np.stack([np.full_like(a, 255), 220 * (1 - a), np.zeros_like(a)], -1).astype(np.uint8)


def write_recon_recording(out, results, *, application_id: str = "wanderland_nav") -> int:
    """Log every `PoseResult` in `results` into `out` (.rrd, written atomically); returns the scene count."""
    out = Path(out)
    if out.suffix != ".rrd":
        raise ValueError(f"out={out}: recordings end in .rrd")
    with atomic_path(out) as tmp:
        rec = rr.RecordingStream(application_id, recording_id=out.stem)
        rec.save(str(tmp))
        try:
            for r in results:  # one subtree per scene (a handful); the cameras of a scene are one batch
                base = f"recon/{entity_name(r.name)}"
                tracks = {"gt": r.gt_centers, "pred_sim3": r.pred_centers_sim3, "pred_se3": r.pred_centers_se3}
                for key, c in tracks.items():
                    c = np.asarray(c, dtype=np.float64)
                    rec.log(f"{base}/{key}", rr.LineStrips3D([c], colors=[_COLORS[key]], radii=0.003), static=True)
                    rec.log(f"{base}/{key}/centers", rr.Points3D(c, colors=[_COLORS[key]], radii=0.005), static=True)
                err = np.linalg.norm(r.pred_centers_sim3 - r.gt_centers, axis=-1)
                rec.log(f"{base}/error", rr.LineStrips3D(np.stack([r.gt_centers, r.pred_centers_sim3], 1),
                                                         colors=_error_colors(err), radii=0.002), static=True)
        finally:
            rec.flush()
            rec.disconnect()
    return len(results)
