"""`degradation_report`: one row of geometry figures for a prepared degraded scene against its grounded source."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from planners import NavMesh

from .build import CORRECTION
from .metrics import feasible_episodes, navmesh_metrics, surface_metrics
from .poses import PoseCorrection


def _mesh(path):
    return trimesh.load(path, file_type="ply", process=False, force="mesh")


def degradation_report(grounded, degraded, *, episodes=(), samples: int = 100_000, seed: int = 0) -> dict:
    """Figures for two PREPARED scenes (`Scene`s with `collision_mesh_path` and `navmesh_path`).

    `episodes`: grounded `Episode`s (scene frame) whose feasibility in the degraded navmesh is counted.
    Surfaces are compared with the grounded collision mesh, and with the ground-truth mesh when the
    grounded scene has one (the demo's `gt_mesh.ply`; completeness over the part its LiDAR saw).
    """
    corr_path = Path(degraded.root) / CORRECTION
    # the grounded scene itself (no correction file) gives the reference row: identity field
    corr = PoseCorrection.load(corr_path) if corr_path.is_file() else PoseCorrection(np.zeros((0, 3)), np.zeros((0, 3, 3)),
                                                                                     np.zeros((0, 3)), 1.0)
    pred = _mesh(degraded.collision_mesh_path)
    fig = surface_metrics(pred, _mesh(grounded.collision_mesh_path), samples=samples, seed=seed)
    row = {"scene": degraded.name, **{f"vs_lidar_mesh/{k}": v for k, v in fig.items()}}
    if grounded.gt_mesh_path is not None:
        fig = surface_metrics(pred, _mesh(grounded.gt_mesh_path), samples=samples, seed=seed,
                              observed=grounded.points)
        row.update({f"vs_gt_mesh/{k}": v for k, v in fig.items()})
    pred_nm, ref_nm = NavMesh.load(degraded.navmesh_path), NavMesh.load(grounded.navmesh_path)
    row.update(navmesh_metrics(pred_nm, ref_nm))
    if episodes:
        starts = np.asarray([e.start_position for e in episodes], dtype=np.float64)
        goals = np.asarray([e.goal_position for e in episodes], dtype=np.float64)
        ok = feasible_episodes(starts, goals, pred_nm, corr)
        row.update({"episodes": int(len(ok)), "episodes_feasible": int(ok.sum())})
    return row
