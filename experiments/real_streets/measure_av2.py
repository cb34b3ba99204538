"""Navmesh of the Argoverse 2 street vs the map's ground truth: road coverage, height error, obstacles.

    PYTHONPATH=$PWD python experiments/real_streets/measure_av2.py [--scene /tmp/av2] [--set ground_fill=false] [--cell-height 0.05] [--png out.png]
    PYTHONPATH=$PWD python experiments/real_streets/measure_av2.py --navigation default [--set navigation.navmesh.agent_max_climb=0.2]

Copies `../shared/data/av2/scene` to `--scene` (if missing), runs `prepare` on it (forced), then
compares `navmesh.npz` with `ground.npz` (the map's ground-height raster, 0.3 m) and `drivable.json`
(drivable-area polygons), all in the shifted city frame (see `../shared/data/av2/README.md`):

* road coverage: grid samples (0.1 m) of the drivable area inside the scanned region (discs of the
  crop radius around the two poses, raster height known) that lie on the navmesh (the nearest navmesh
  point is within 0.05 m horizontally); "seen road" restricts that to samples within 1 m of a LiDAR
  ground return (|dz| to the raster < 0.3 m);
* height: |z_navmesh - z_ground| over area-uniform navmesh samples with a raster cell;
* obstacles: LiDAR returns 0.3..2 m above the raster ground (cars, poles, walls) whose x, y lie on the
  navmesh, and of those the ones 0.3..2 m above the navmesh floor there (an agent would walk into them).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from wanderland_nav.preparation.scene import prepare_scene
from wanderland_nav.scene.collision import CollisionSettings
from wanderland_nav.scene.types import points_in_polygon

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "av2"


def raster_height(ground, xy: np.ndarray) -> np.ndarray:
    """Map ground height at shifted-frame `xy [N,2]` (NaN outside the raster or where it has no ground)."""
    h = ground["height"]
    col = np.floor(ground["col_from_x"][0] * xy[:, 0] + ground["col_from_x"][1]).astype(np.int64)
    row = np.floor(ground["row_from_y"][0] * xy[:, 1] + ground["row_from_y"][1]).astype(np.int64)
    ok = (row >= 0) & (row < h.shape[0]) & (col >= 0) & (col < h.shape[1])
    out = np.full(len(xy), np.nan)
    out[ok] = h[row[ok], col[ok]]
    return out


def on_navmesh(nm, xyz: np.ndarray, tol: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """(`bool [N]` x, y lies on the navmesh, `[N]` navmesh z there) for scene-frame `xyz`."""
    snapped = nm.snap_point(xyz, max_distance=1e9)
    return np.linalg.norm(snapped[:, :2] - xyz[:, :2], axis=1) <= tol, snapped[:, 2]


def plot(png: Path, nm, polys, poses, obst, road_xy, covered) -> None:
    """Top-down: drivable polygons, navmesh (grey), road samples not on it (red), obstacle returns (black)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    fig, ax = plt.subplots(figsize=(8, 8))
    for p in polys:
        ax.fill(p[:, 0], p[:, 1], color="tab:blue", alpha=0.15, lw=0)
    ax.add_collection(PolyCollection(nm.verts_xy[nm.tris] + nm.bmin[:2], facecolors="0.6", alpha=0.6, lw=0))
    miss = road_xy[~covered][::7]
    ax.scatter(miss[:, 0], miss[:, 1], s=1, c="tab:red", lw=0, label="road not on the navmesh")
    ax.scatter(obst[::3, 0], obst[::3, 1], s=1, c="k", lw=0, label="obstacle returns (0.3-2 m)")
    ax.plot(poses[:, 0], poses[:, 1], "o", c="tab:green", label="poses")
    lo, hi = road_xy.min(0) - 2, road_xy.max(0) + 2
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), aspect="equal", xlabel="x (m)", ylabel="y (m)",
           title="av2 street: navmesh (grey) on drivable area (blue)")
    ax.legend(loc="upper right", markerscale=6, fontsize=8)
    fig.savefig(png, dpi=110, bbox_inches="tight")
    plt.close(fig)


def navigation_group(name: str, overrides=()):
    """The project's composed `navigation=<name>` group (collision and navmesh settings), as every entry point
    composes it."""
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config

    return typed_config(compose_config("prepare", [f"navigation={name}", *overrides]), PrepareConfig).navigation


def measure(scene_dir: Path, settings: CollisionSettings, cell_height: float, png: Path | None = None,
            max_climb: float | None = None, navmesh=None) -> dict:
    """`navmesh`: a composed group's `NavMeshSettings` (then `cell_height` / `max_climb` are not used)."""
    from planners import NavMesh, NavMeshSettings

    if navmesh is None:
        navmesh = NavMeshSettings(up_axis="+z", cell_height=cell_height,
                                  **({} if max_climb is None else {"agent_max_climb": max_climb}))
    else:
        navmesh = dataclasses.replace(navmesh, up_axis="+z")
    scene = prepare_scene(scene_dir, force=True, collision=settings, navmesh=navmesh)
    nm = NavMesh.load(scene.navmesh_path)
    ground = dict(np.load(DATA / "ground.npz"))
    polys = [np.asarray(p["xyz"])[:, :2] for p in json.loads((DATA / "drivable.json").read_text())["polygons"]]
    poses = np.loadtxt(scene_dir / "lidar" / "poses.txt", ndmin=2).reshape(-1, 3, 4)[:, :, 3]

    # road samples: 0.1 m grid over the scanned region, on drivable area with a known ground height
    r = settings.crop_radius
    lo, hi = poses[:, :2].min(0) - r, poses[:, :2].max(0) + r
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 0.1), np.arange(lo[1], hi[1], 0.1), indexing="ij")
    xy = np.stack([gx.ravel(), gy.ravel()], -1)
    xy = xy[cKDTree(poses[:, :2]).query(xy)[0] <= r]
    drivable = np.zeros(len(xy), bool)
    for p in polys:  # 13 polygons; the points are batched
        drivable |= points_in_polygon(xy, p)
    z = raster_height(ground, xy)
    road = drivable & np.isfinite(z)
    road_xyz = np.column_stack([xy[road], z[road]])
    covered, _ = on_navmesh(nm, road_xyz)

    pts = scene.points.astype(np.float64)
    dz_pts = pts[:, 2] - raster_height(ground, pts[:, :2])
    ground_pts = pts[np.abs(dz_pts) < 0.3]
    seen = cKDTree(ground_pts[:, :2]).query(road_xyz[:, :2], distance_upper_bound=1.0)[0] <= 1.0

    samples = nm.random_navigable_points(20000, seed=0)
    zg = raster_height(ground, samples[:, :2])
    dz = (samples[:, 2] - zg)[np.isfinite(zg)]

    obst = pts[(dz_pts > 0.3) & (dz_pts < 2.0)]
    obst = obst[cKDTree(poses[:, :2]).query(obst[:, :2])[0] <= r]
    obst_on, z_nav = on_navmesh(nm, np.column_stack([obst[:, :2], obst[:, 2] - 1.0]))
    above = obst[:, 2] - z_nav  # how far each return sits above the navmesh floor under it
    blocking = obst_on & (above > 0.3) & (above < 2.0)
    if png is not None:
        plot(png, nm, polys, poses, obst, road_xyz[:, :2], covered)
    cell = 0.1 * 0.1
    return {
        "ground_fill": settings.ground_fill, "cell_height": navmesh.cell_height, "navmesh_area_m2": nm.area,
        "agent": {k: getattr(navmesh, k) for k in ("agent_radius", "agent_height", "agent_max_climb", "agent_max_slope")},
        "islands": len(nm.islands), "largest_island_m2": max((i.area for i in nm.islands), default=0.0),
        "filled_area_m2": scene.meta["prepare"]["collision_mesh"].get("ground_fill", {}).get("filled_area_m2", 0.0),
        "road_m2": road.sum() * cell, "road_covered": float(covered.mean()),
        "seen_road_m2": seen.sum() * cell, "seen_road_covered": float(covered[seen].mean()),
        "abs_dz_median": float(np.median(np.abs(dz))), "abs_dz_p90": float(np.quantile(np.abs(dz), 0.9)),
        "signed_dz_median": float(np.median(dz)), "within_0.15m": float((np.abs(dz) <= 0.15).mean()),
        "samples_with_raster": float(np.isfinite(zg).mean()),
        "obstacle_returns": len(obst), "obstacle_returns_on_navmesh": int(obst_on.sum()),
        "obstacle_returns_in_walk_space": int(blocking.sum()),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=Path, default=Path("/tmp/av2_street"))
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                    help="CollisionSettings fields, e.g. ground_fill=false ground_window=5")
    ap.add_argument("--cell-height", type=float, default=0.2, help="navmesh cell height (m): its floors round up")
    ap.add_argument("--max-climb", type=float, default=None, help="navmesh agent_max_climb (m); default: the project's")
    ap.add_argument("--png", type=Path, default=None, help="write a top-down figure here")
    ap.add_argument("--navigation", default=None, metavar="NAME",
                    help="the project's navigation=NAME group (default | street | recast | habitat) for both the "
                         "collision and the navmesh settings; then --set takes navigation.* overrides")
    a = ap.parse_args(argv)
    if a.navigation is not None:
        if not (a.scene / "lidar").is_dir():
            shutil.copytree(DATA / "scene", a.scene)
        group = navigation_group(a.navigation, a.set)
        m = measure(a.scene, group.collision, cell_height=group.navmesh.cell_height, png=a.png, navmesh=group.navmesh)
        report(m, f"navigation={a.navigation} {' '.join(a.set)}".strip())
        return

    if not (a.scene / "lidar").is_dir():
        shutil.copytree(DATA / "scene", a.scene)
    fields = {f.name: f.type for f in dataclasses.fields(CollisionSettings)}
    kw = {k: (v.lower() == "true") if fields[k] in (bool, "bool") else float(v)
          for k, v in (kv.split("=", 1) for kv in a.set)}
    m = measure(a.scene, CollisionSettings(**kw), cell_height=a.cell_height, png=a.png, max_climb=a.max_climb)
    report(m, f"ground_fill={m['ground_fill']}")


def report(m: dict, what: str) -> None:
    print(f"av2 street, {what}, navmesh cell_height {m['cell_height']} m, agent {m['agent']}: navmesh "
          f"{m['navmesh_area_m2']:.0f} m2 in {m['islands']} islands (largest {m['largest_island_m2']:.0f} m2; ground "
          f"infill added {m['filled_area_m2']:.0f} m2)")
    print(f"  road in the 15 m region: {m['road_m2']:.0f} m2, on the navmesh {100 * m['road_covered']:.1f} %")
    print(f"  seen road (within 1 m of a ground return): {m['seen_road_m2']:.0f} m2, "
          f"on the navmesh {100 * m['seen_road_covered']:.1f} %")
    print(f"  navmesh height vs map ground ({100 * m['samples_with_raster']:.0f} % of samples have a raster cell): "
          f"|dz| median {m['abs_dz_median']:.3f} m, p90 {m['abs_dz_p90']:.3f} m, signed median "
          f"{m['signed_dz_median']:+.3f} m, within 0.15 m {100 * m['within_0.15m']:.1f} %")
    print(f"  obstacle returns (0.3-2 m above ground) on the navmesh: {m['obstacle_returns_on_navmesh']} "
          f"of {m['obstacle_returns']}; of those 0.3-2 m above the navmesh floor (in the agent's way): "
          f"{m['obstacle_returns_in_walk_space']}")


if __name__ == "__main__":
    sys.exit(main())
