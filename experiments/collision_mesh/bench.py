"""Collision-mesh benchmark: accuracy vs the demo scene's ground truth, time and peak memory vs N.

    python experiments/collision_mesh/bench.py [--scene /tmp/demo] [--preset default]
        [--voxels 0.1 0.15 0.2] [--sizes 1000000 5000000] [--kitti /work/shared/data/lidar/kitti]

Accuracy (on the procedural demo, `gt_mesh.ply` is the exact geometry the LiDAR was simulated from):
  * acc      mean distance collision-mesh samples -> GT surface (m), and precision@tau
  * comp     mean distance GT samples -> collision mesh (m), completeness@tau; computed on GT
             samples inside the crop region (radius + height band around the trajectory), and on
             "observed" GT samples (within `--observed` m of a LiDAR point): the first counts what
             the scanner never saw, the second isolates what meshing loses
  * chamfer  symmetric Chamfer = (acc + comp_crop) / 2
Scaling: the demo cloud resampled (with 1 cm jitter) to each N; every size runs in a fresh
subprocess so `ru_maxrss` and tracemalloc's peak are its own.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from wanderland_nav.geometry import nav_from_scene_rotation
from wanderland_nav.scene import extract_collision_mesh, load_scene
from wanderland_nav.scene.collision import CollisionSettings, crop_to_trajectory
from wanderland_nav.scene.pointcloud import read_kitti_bin


def accuracy(scene, mesh: trimesh.Trimesh, settings: CollisionSettings, tau: float, observed: float,
             n_samples: int = 400_000) -> dict:
    gt = trimesh.load(scene.gt_mesh_path, process=False, force="mesh")
    pg, _ = trimesh.sample.sample_surface(gt, n_samples, seed=0)
    pr, _ = trimesh.sample.sample_surface(mesh, n_samples, seed=1)
    R = nav_from_scene_rotation(scene.up_axis)
    in_crop = crop_to_trajectory((pg @ R.T).astype(np.float32), scene.camera_centers() @ R.T, settings.crop_radius,
                                 settings.height_band)
    seen = cKDTree(scene.points).query(pg, distance_upper_bound=observed)[0] < observed
    d_rg = cKDTree(pg).query(pr)[0]
    d_gr = cKDTree(pr).query(pg)[0]
    crop, obs = d_gr[in_crop], d_gr[in_crop & seen]
    return {"acc_m": float(d_rg.mean()), f"precision@{tau}": float((d_rg < tau).mean()),
            "comp_crop_m": float(crop.mean()), f"completeness_crop@{tau}": float((crop < tau).mean()),
            "comp_observed_m": float(obs.mean()), f"completeness_observed@{tau}": float((obs < tau).mean()),
            "chamfer_m": float(0.5 * (d_rg.mean() + crop.mean())),
            "gt_samples_in_crop": float(in_crop.mean()), "gt_in_crop_observed": float(seen[in_crop].mean())}


def _proc_status_mb(field: str) -> float:
    """VmRSS / VmHWM of this process in MiB (Linux /proc; ru_maxrss would include the parent's peak)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _reset_peak_rss() -> None:
    """Reset VmHWM to the current RSS (Linux clear_refs 5), so the peak is the extraction's own."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _scaling_worker(args):
    scene_path, n, voxel, q = args
    scene = load_scene(scene_path)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, len(scene.points), n)
    pts = (scene.points[idx] + rng.normal(0, 0.01, (n, 3))).astype(np.float32)
    cams = scene.camera_centers()
    rss_before = _proc_status_mb("VmRSS")
    _reset_peak_rss()
    tracemalloc.start()
    t0 = time.perf_counter()
    m = extract_collision_mesh(pts, cams, scene.up_axis, settings=CollisionSettings(voxel_size=voxel))
    dt = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    t0 = time.perf_counter()
    extract_collision_mesh(pts, cams, scene.up_axis, settings=CollisionSettings(voxel_size=voxel))
    dt_untraced = time.perf_counter() - t0
    hwm = _proc_status_mb("VmHWM")
    q.put({"n": n, "voxel": voxel, "seconds": dt_untraced, "seconds_traced": dt, "faces": int(len(m.faces)),
           "input_mb": pts.nbytes / 2**20, "tracemalloc_peak_mb": peak / 2**20,
           "rss_before_mb": rss_before, "peak_rss_mb": hwm, "peak_rss_increase_mb": hwm - rss_before,
           "stages": m.metadata["collision"]["timings"]})


def scaling(scene_path: Path, sizes, voxel: float) -> list[dict]:
    ctx = mp.get_context("spawn")
    out = []
    for n in sizes:
        q = ctx.Queue()
        p = ctx.Process(target=_scaling_worker, args=((str(scene_path), n, voxel, q),))
        p.start()
        out.append(q.get())
        p.join()
    return out


def kitti(folder: Path, voxel: float) -> dict:
    xyz = read_kitti_bin(folder / "000000.bin")[:, :3]
    t0 = time.perf_counter()
    m = extract_collision_mesh(xyz, np.zeros((1, 3)), "+z", settings=CollisionSettings(voxel_size=voxel,
                                                                                       crop_radius=20.0))
    dt = time.perf_counter() - t0
    c, n = m.triangles_center, m.face_normals
    road = (n[:, 2] > 0.9) & (np.linalg.norm(c[:, :2], axis=1) < 10)
    return {"points": int(len(xyz)), "seconds": dt, "faces": int(len(m.faces)),
            "road_faces": int(road.sum()), "road_z_median": float(np.median(c[road, 2]))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="/tmp/wanderland_bench/demo")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--voxels", type=float, nargs="+", default=[0.1, 0.15, 0.2])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1_000_000, 5_000_000])
    ap.add_argument("--scaling-voxel", type=float, default=0.15)
    ap.add_argument("--tau", type=float, default=0.2)
    ap.add_argument("--observed", type=float, default=0.25)
    ap.add_argument("--kitti", default=str(Path(__file__).resolve().parents[3] / "shared/data/lidar/kitti"))
    ap.add_argument("--json", default=None, help="also write all figures to this file")
    a = ap.parse_args(argv)

    from wanderland_nav.scene import make_demo_scene  # not imported in the spawned scaling workers

    t0 = time.perf_counter()
    path = make_demo_scene(Path(a.scene), seed=0, preset=a.preset)
    scene = load_scene(path)
    print(f"demo scene ({a.preset}): {len(scene.points):,} points, {len(scene.cameras)} cameras, "
          f"ready in {time.perf_counter() - t0:.1f}s", flush=True)
    res = {"accuracy": [], "scaling": [], "kitti": None}
    print(f"\naccuracy vs gt_mesh.ply (tau = {a.tau} m)")
    print(f"{'voxel':>6} {'faces':>9} {'time s':>7} {'acc m':>7} {'prec':>6} {'comp m':>7} {'compl':>6} "
          f"{'comp_obs m':>10} {'compl_obs':>9} {'chamfer m':>9}")
    for v in a.voxels:
        st = CollisionSettings(voxel_size=v)
        t = time.perf_counter()
        m = extract_collision_mesh(scene.points, scene.camera_centers(), scene.up_axis, settings=st)
        dt = time.perf_counter() - t
        r = {"voxel": v, "faces": int(len(m.faces)), "seconds": dt, **accuracy(scene, m, st, a.tau, a.observed)}
        res["accuracy"].append(r)
        print(f"{v:6.2f} {r['faces']:9,d} {dt:7.2f} {r['acc_m']:7.3f} {r[f'precision@{a.tau}']:6.3f} "
              f"{r['comp_crop_m']:7.3f} {r[f'completeness_crop@{a.tau}']:6.3f} {r['comp_observed_m']:10.3f} "
              f"{r[f'completeness_observed@{a.tau}']:9.3f} {r['chamfer_m']:9.3f}", flush=True)
    print(f"  (GT samples in crop region: {res['accuracy'][0]['gt_samples_in_crop']:.2f}; "
          f"of those observed by the LiDAR: {res['accuracy'][0]['gt_in_crop_observed']:.2f})")

    print(f"\nscaling (voxel {a.scaling_voxel} m, fresh process per size)")
    print(f"{'N':>10} {'time s':>7} {'faces':>9} {'input MB':>8} {'tracemalloc peak MB':>19} "
          f"{'peak RSS MB':>11} {'RSS increase MB':>15}")
    for r in scaling(path, a.sizes, a.scaling_voxel):
        res["scaling"].append(r)
        print(f"{r['n']:10,d} {r['seconds']:7.2f} {r['faces']:9,d} {r['input_mb']:8.1f} "
              f"{r['tracemalloc_peak_mb']:19.1f} {r['peak_rss_mb']:11.1f} {r['peak_rss_increase_mb']:15.1f}  stages {json.dumps({k: round(x, 2) for k, x in r['stages'].items()})}",
              flush=True)

    kdir = Path(a.kitti)
    if (kdir / "000000.bin").is_file():
        k = kitti(kdir, 0.2)
        res["kitti"] = k
        print(f"\nKITTI 000000.bin ({k['points']:,} pts, voxel 0.2, radius 20 m): {k['faces']:,} faces in "
              f"{k['seconds']:.2f}s; road (upward faces < 10 m) median z = {k['road_z_median']:.2f} m "
              "(sensor ~1.73 m above the road)")
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
