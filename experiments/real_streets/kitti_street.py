"""The six real KITTI scans as a LiDAR-only v2 scene: prepare, expert episodes, top-down figure, figures.

    PYTHONPATH=$PWD python experiments/real_streets/kitti_street.py [--scene /tmp/kitti_street] [--png out.png]

Builds `--scene` from `../shared/data/lidar/kitti` (`lidar/00000{0..5}.bin`, `lidar/poses.txt` = the
GICP poses, `scene_meta.json` with `lidar_min_range` 2.7 m for the car's own roof returns), then for
ground infill off and on: prepare (forced), the share of road returns near the sensor path (within
8 m, within 0.25 m of the road plane 1.73 m under the sensor) that lie on the navmesh, whether the
road under each sensor pose is navigable, the navmesh floor's height above those road returns (KITTI has no
ground-truth raster: the returns themselves are the reference, |dz| median / p90 over the returns whose x, y
lie on the navmesh), and 50 expert episodes (kept, off-mesh rejections). The
figure (navmesh, LiDAR trajectory, expert paths) is written with infill on.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

from wanderland_nav.episodes.generate import GeneratorSettings, generate_episodes
from wanderland_nav.preparation.scene import prepare_scene
from wanderland_nav.scene.collision import CollisionSettings
from wanderland_nav.viz.topdown import plot_topdown

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "lidar" / "kitti"
SENSOR_HEIGHT = 1.73


def make_scene(root: Path) -> None:
    (root / "lidar").mkdir(parents=True, exist_ok=True)
    for f in sorted(DATA.glob("*.bin")):
        shutil.copy(f, root / "lidar" / f.name)
    shutil.copy(DATA / "gicp_poses_kitti_format.txt", root / "lidar" / "poses.txt")
    (root / "scene_meta.json").write_text(json.dumps({"name": "kitti_street", "lidar_min_range": 2.7}))


def run(root: Path, ground_fill: bool, png: Path | None) -> dict:
    from planners import NavMesh

    scene = prepare_scene(root, force=True, collision=CollisionSettings(ground_fill=ground_fill))
    nm = NavMesh.load(scene.navmesh_path)
    path = scene.capture_positions()
    p = scene.points
    near = np.linalg.norm(p[:, None, :2] - path[None, :, :2], axis=-1).min(1) < 8.0
    road = p[near & (np.abs(p[:, 2] - (path[:, 2].mean() - SENSOR_HEIGHT)) < 0.25)]
    snapped = nm.snap_point(road, max_distance=1e9)
    dz = (snapped[:, 2] - road[:, 2])[np.linalg.norm(snapped[:, :2] - road[:, :2], axis=1) <= 0.05]
    eps, summary = generate_episodes(scene, nm, num_episodes=50, seed=0,
                                     settings=GeneratorSettings(goal_images=False))
    if png is not None:
        plot_topdown(png, nav_from_scene=scene.nav_from_scene, camera_centers=path, episodes=eps, navmesh=nm,
                     title=f"KITTI street (6 real scans): navmesh {nm.area:.0f} m2, {len(eps)} expert episodes")
    fill = scene.meta["prepare"]["collision_mesh"].get("ground_fill") or {}
    return {"ground_fill": ground_fill, "area": nm.area, "filled": fill.get("filled_area_m2", 0.0),
            "road_on_mesh": float(nm.is_navigable(road, max_height_delta=0.4).mean()), "road_points": len(road),
            "dz_median": float(np.median(np.abs(dz))), "dz_p90": float(np.quantile(np.abs(dz), 0.9)),
            "dz_signed": float(np.median(dz)),
            "under_path": int(nm.is_navigable(path - [0, 0, SENSOR_HEIGHT], max_height_delta=0.4).sum()),
            "poses": len(path), "kept": len(eps), "candidates": summary.candidates,
            "off_mesh": summary.rejections["off_mesh"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=Path, default=Path("/tmp/kitti_street"))
    ap.add_argument("--png", type=Path, default=Path(__file__).with_name("kitti_street_topdown.png"))
    a = ap.parse_args(argv)
    make_scene(a.scene)
    for fill in (False, True):
        m = run(a.scene, fill, a.png if fill else None)
        print(f"ground_fill={fill}: navmesh {m['area']:.0f} m2 (infill {m['filled']:.0f} m2); road returns near the "
              f"path on the navmesh {100 * m['road_on_mesh']:.1f} % of {m['road_points']:,}, floor above them |dz| "
              f"median {m['dz_median']:.3f} m, p90 {m['dz_p90']:.3f} m (signed median {m['dz_signed']:+.3f}); road under the sensor "
              f"navigable at {m['under_path']}/{m['poses']} poses; expert episodes {m['kept']}/50, off-mesh "
              f"rejections {m['off_mesh']}/{m['candidates']} candidates")


if __name__ == "__main__":
    sys.exit(main())
