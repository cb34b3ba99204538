"""What `size=paper` gives on a district's layout, without building it: image, scan and LiDAR-point counts
and the Gaussian count at the paper's density.

    python experiments/districts/paper_counts.py --seed 0 --scan-subsample 25

Exact: the capture poses and scans along the same paths at the paper size's spacings (images, scans, rays).
Measured on a subsample: the LiDAR hit fraction within the paper size's range (every `--scan-subsample`-th
scan fired with the paper's beam count). Estimated: Gaussians = the area of the triangles the small size's
cameras and LiDAR see, divided by the paper size's splat spacing squared (the expected number of lattice
points on those faces; the paper size's denser capture sees at least these faces, so this is a lower
bound in that respect, and every seen face of a 100 m district lies within its 25 m splat range).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wanderland_nav.scene.demo import capture, lidar, views
from wanderland_nav.scene.demo.raycast import RayCaster
from wanderland_nav.scene.district import SIZES, build_district


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scan-subsample", type=int, default=25)
    a = ap.parse_args()
    t0 = time.process_time()
    d = build_district(a.seed)
    lay, small, paper = d.layout, SIZES["small"], SIZES["paper"]
    caster = RayCaster(lay.vertices, lay.faces)
    rig = capture.make_rig(paper.frame_spacing, a.seed, paper.val_spacing, d.paths, lay.walk_height)
    images = 2 * len(rig.position)
    scans = np.concatenate([capture.sample_path(p, paper.scan_spacing, lay.walk_height)[0] for p in d.paths])
    sensors = scans + np.array([0.0, 0.0, lidar.SENSOR_ABOVE_RIG])
    sub = sensors[:: a.scan_subsample]
    xyz, _, _, _ = lidar.scan(caster, lay, sub, lidar.ScanPattern(rays=paper.lidar_rays), paper.lidar_range,
                              paper.lidar_noise, a.seed)
    hit = len(xyz) / (len(sub) * paper.lidar_rays)
    # the faces the small size sees (its cameras and LiDAR), their area
    rig_s = capture.make_rig(small.frame_spacing, a.seed, small.val_spacing, d.paths, lay.walk_height)
    T, _, _ = capture.stereo_cameras(rig_s)
    K = capture.intrinsics(small.image_size)
    *_, seen_img = views.render_views(caster, lay, T, K, small.image_size, small.image_size, a.seed)
    scans_s = np.concatenate([capture.sample_path(p, small.scan_spacing, lay.walk_height)[0] for p in d.paths])
    *_, seen_l = lidar.scan(caster, lay, scans_s + np.array([0.0, 0.0, lidar.SENSOR_ABOVE_RIG]),
                            lidar.ScanPattern(rays=small.lidar_rays), small.lidar_range, small.lidar_noise, a.seed)
    seen = np.union1d(seen_img, seen_l)
    v = lay.vertices[lay.faces[seen]]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()
    print(f"district seed {a.seed}: {d.plan.W:.0f} x {d.plan.H:.0f} m, {len(lay.faces):,} triangles")
    print(f"paper size: {images:,} images of {paper.image_size} px, {len(sensors):,} scans x {paper.lidar_rays:,} beams "
          f"= {len(sensors) * paper.lidar_rays / 1e6:.1f}M rays; hit fraction within {paper.lidar_range:g} m on "
          f"{len(sub)} scans: {hit:.3f} -> {len(sensors) * paper.lidar_rays * hit / 1e6:.1f}M LiDAR points")
    print(f"seen surface (small size's capture): {area:,.0f} m^2 -> {area / paper.splat_spacing ** 2 / 1e6:.2f}M "
          f"Gaussians at {paper.splat_spacing} m spacing (small size: {area / small.splat_spacing ** 2 / 1e3:.0f}k "
          f"expected at {small.splat_spacing} m)")
    print(f"cpu {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
