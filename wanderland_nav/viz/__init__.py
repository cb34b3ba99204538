"""Visualisation: top-down plots (matplotlib) and rerun logging. The only package that imports them.

rerun modules: `rerun_scene` (mesh, navmesh, points, capture cameras), `rerun_episodes` (start, goal,
expert path), `rerun_rollout` (per-step agent pose, camera, waypoints, scalars), `blueprint` (default
layout), `rerun_logger.RerunLogger` (the trainer's `logger=rerun`). Imported lazily so that
`import wanderland_nav.viz` (e.g. for `topdown`) does not load rerun.
"""


def __getattr__(name):
    if name == "RerunLogger":
        from wanderland_nav.viz.rerun_logger import RerunLogger

        return RerunLogger
    raise AttributeError(f"module 'wanderland_nav.viz' has no attribute {name!r}")
