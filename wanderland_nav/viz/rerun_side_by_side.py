"""Grounded and degraded collision meshes side by side in one rerun recording (`.rrd`).

Each mesh is shifted along the scene's x axis so that the environments lie in a row with a gap
between their bounding boxes, and labelled with its name at its centre: the holes, fragments and
scale of a degraded environment are visible next to the grounded one at a glance.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import rerun as rr

from wanderland_nav.atomic import atomic_path
from wanderland_nav.scene.collision import load_collision_mesh


def write_side_by_side(out: str | Path, meshes: Mapping[str, str | Path], *, gap: float = 5.0) -> dict[str, float]:
    """`meshes`: label -> `collision_mesh.ply` (scene frame, metres). -> label -> x offset applied (m)."""
    out = Path(out)
    if out.suffix != ".rrd":
        raise ValueError(f"out={out}: recordings end in .rrd")
    offsets: dict[str, float] = {}
    with atomic_path(out) as tmp:
        rec = rr.RecordingStream("wanderland_nav_study", recording_id=out.stem)
        rec.save(str(tmp))
        try:
            x = 0.0
            for i, (label, path) in enumerate(meshes.items()):
                mesh = load_collision_mesh(path)
                v = np.asarray(mesh.vertices, np.float64)  # [V, 3] scene frame
                shift = x - v[:, 0].min()
                offsets[label] = float(shift)
                pos = (v + [shift, 0.0, 0.0]).astype(np.float32)
                rec.log(f"world/{label}/mesh", rr.Mesh3D(vertex_positions=pos,
                                                         triangle_indices=np.asarray(mesh.faces, np.int64),
                                                         albedo_factor=[0.55 + 0.1 * (i % 4), 0.7, 0.8, 1.0]),
                        static=True)
                centre = pos.mean(0)
                rec.log(f"world/{label}/label", rr.Points3D([centre], labels=[label], radii=0.5), static=True)
                x = float(pos[:, 0].max()) + gap
        finally:
            rec.flush()
            rec.disconnect()
    return offsets
