"""`python -m wanderland_nav.prepare scene=demo`: make (demo) + prepare a scene, print a summary.

Thin Hydra entry point: composes `conf/prepare.yaml`, converts the config into typed settings
(`CollisionSettings`, `planners.NavMeshSettings`) and calls `scene_preparation.prepare_scene`.
`scene=<folder>` (not a conf/scene/ option) is moved to `scene_path` before Hydra sees it.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import hydra
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from wanderland_nav.scene_preparation import prepare_scene
from wanderland_nav.scene.collision import CollisionSettings

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
log = logging.getLogger("wanderland_nav.prepare")


def settings_from_cfg(cfg: DictConfig):
    """Typed settings from the composed config (library code never sees the DictConfig)."""
    c = OmegaConf.to_container(cfg.collision, resolve=True)
    c["height_band"] = tuple(c["height_band"])
    collision = CollisionSettings(**c)
    navmesh = None
    if cfg.navmesh_enabled:
        from planners import NavMeshSettings

        navmesh = NavMeshSettings(**OmegaConf.to_container(cfg.navmesh, resolve=True))
    return collision, navmesh


def _took(side: dict) -> str:
    return "cached" if side.get("skipped") else f"{side['timings']['total_s']:.1f}s"


def run(cfg: DictConfig) -> dict:
    t0 = time.perf_counter()
    collision, navmesh = settings_from_cfg(cfg)
    if cfg.scene_path is not None:
        path = Path(to_absolute_path(str(cfg.scene_path)))
        made = None
    else:
        path = Path(to_absolute_path(str(cfg.scene.path)))
        made = None  # seconds spent making the demo scene (None: not a demo)
        if cfg.scene.get("demo", False):
            from wanderland_nav.scene import make_demo_scene

            t = time.perf_counter()
            make_demo_scene(path, seed=int(cfg.scene.get("seed", 0)), preset=str(cfg.scene.get("preset", "default")))
            made = time.perf_counter() - t
    up = cfg.get("up_axis") or cfg.scene.get("up_axis")
    scene = prepare_scene(path, force=bool(cfg.force), collision=collision, navmesh=navmesh, up_axis=up,
                          bake_navmesh=bool(cfg.navmesh_enabled))
    rep = scene.meta["prepare"]
    cm = rep["collision_mesh"]
    lines = [f"scene {scene.name} ({scene.version}) at {scene.root}",
             f"  up axis {scene.up_axis} (from {scene.up_axis_source}); environment {scene.environment}",
             f"  points {len(scene.points):,}; cameras {len(scene.cameras)} "
             f"({sum(c.split == 'val' for c in scene.cameras)} val)"]
    if made is not None:
        lines.append(f"  demo scene ready in {made:.1f}s")
    lines.append(f"  collision mesh: {cm['faces']:,} faces from {cm['points_kept']:,}/{cm['points_in']:,} points"
                 f" ({_took(cm)})")
    if "navmesh" in rep:
        nm = rep["navmesh"]
        lines.append(f"  navmesh: {nm['area_m2']:.0f} m2 walkable in {nm['num_islands']} island(s) ({_took(nm)})")
    lines.append(f"  total {time.perf_counter() - t0:.1f}s")
    print("\n".join(lines), flush=True)
    return rep


@hydra.main(version_base="1.3", config_path="../conf", config_name="prepare")
def main(cfg: DictConfig) -> None:
    run(cfg)


def rewrite_scene_override(argv: list[str], conf_dir: Path = CONF_DIR) -> list[str]:
    """`scene=X` -> `scene_path=X` unless X names a config in conf/scene/ (`scene` is a Hydra group)."""
    out = []
    for a in argv:
        if a.startswith("scene=") and not (conf_dir / "scene" / f"{a[6:]}.yaml").is_file():
            a = "scene_path=" + a[6:]
        out.append(a)
    return out


if __name__ == "__main__":
    sys.argv = [sys.argv[0]] + rewrite_scene_override(sys.argv[1:])
    main()
