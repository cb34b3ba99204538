"""`python -m wanderland_nav.prepare [scene=demo | scene=<folder> | scene=<set>]`: make (demo) + prepare scenes.

Collision mesh and navmesh settings come from `conf/navigation/` (the group train, evaluate and
make_episodes compose too); steps whose outputs are up to date are skipped (`preparation.scene`).
A scene set (`scene=demo_set`, or any `scene.set` block) is prepared scene by scene in parallel and resumably
(`compose.scene_sets.run_set_jobs`): failed scenes are listed at the end and the exit status is 1.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

import time

from omegaconf import DictConfig

from wanderland_nav.compose import prepared_scene, typed_config
from wanderland_nav.compose.scene import names_set
from wanderland_nav.compose.scene_sets import run_set_jobs
from wanderland_nav.compose.schema import PrepareConfig


def _took(side: dict) -> str:
    return "cached" if side.get("skipped") else f"{side['timings']['total_s']:.1f}s"


def run(cfg: DictConfig):
    """Everything `main` does (tests call it with a composed config). Returns the preparation report
    (a scene set: the `preparation.scene_set.BatchReport`)."""
    t0 = time.perf_counter()
    c: PrepareConfig = typed_config(cfg, PrepareConfig)
    if names_set(c.scene):  # a set: its resumable batch jobs, one report row per scene
        if not c.navmesh_enabled:
            raise ValueError("navmesh_enabled=false: a scene set is always prepared with its navmesh")
        return run_set_jobs(c.scene, c.navigation, generator=None, force=c.force, workers=c.workers)
    scene = prepared_scene(c.scene, c.navigation, force=c.force, bake_navmesh=c.navmesh_enabled, prepare=True)
    rep = scene.meta["prepare"]
    cm = rep["collision_mesh"]
    lines = [f"scene {scene.name} ({scene.version}) at {scene.root}",
             f"  up axis {scene.up_axis} (from {scene.up_axis_source}); environment {scene.environment}",
             f"  points {len(scene.points):,}; cameras {len(scene.cameras)} "
             f"({sum(cam.split == 'val' for cam in scene.cameras)} val)",
             f"  collision mesh: {cm['faces']:,} faces from {cm['points_kept']:,}/{cm['points_in']:,} points"
             f" ({_took(cm)})"]
    if cm.get("ground_fill"):
        g = cm["ground_fill"]
        lines.append(f"  ground sheet: {g.get('sheet_area_m2', 0.0):.0f} m2 at the measured ground height, "
                     f"{g['filled_area_m2']:.0f} m2 of it filled where the scan saw no ground")
    lf = cm.get("lidar_filter")
    if lf and lf["min_range_m"] > 0:
        lines.append(f"  LiDAR self-returns: {lf['points_dropped']:,} within {lf['min_range_m']} m of the sensor "
                     f"dropped ({lf['source']})")
    if "navmesh" in rep:
        nm = rep["navmesh"]
        lines.append(f"  navmesh: {nm['area_m2']:.0f} m2 walkable in {nm['num_islands']} island(s) ({_took(nm)})")
    lines.append(f"  total {time.perf_counter() - t0:.1f}s")
    print("\n".join(lines), flush=True)
    return rep


main = entry_point("prepare", run)


if __name__ == "__main__":
    main()
