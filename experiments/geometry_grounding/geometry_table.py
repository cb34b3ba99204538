"""Geometry of the degraded environments against the grounded one: the table in README.md.

    python experiments/geometry_grounding/geometry_table.py --out /tmp/grounding --preset tiny --seeds 0 1 2
    python experiments/real_streets/kitti_street.py --scene <dir>/kitti_street
    python experiments/geometry_grounding/geometry_table.py --out /tmp/grounding_kitti --kitti <dir>/kitti_street --seeds 0 1 2

Builds the demo block (or uses --scene), prepares it, generates its grounded expert episodes, then for
every degradation preset and seed builds, prepares and measures the degraded copy. Prints one markdown
row per preset: mean over seeds with [min, max] (deterministic presets run once), plus the grounded
scene's own row against the ground-truth mesh as the reference. `--kitti <folder>`: the six real KITTI scans as a
LiDAR-only scene, the folder `experiments/real_streets/kitti_street.py` builds; presets that need a splat are reported
as not applicable, with the builder's reason.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

COLUMNS = ("vs_gt_mesh/chamfer_m", "vs_gt_mesh/accuracy@10cm", "vs_gt_mesh/completeness@10cm",
           "vs_lidar_mesh/chamfer_m", "vs_lidar_mesh/completeness@20cm", "walkable_m2", "islands", "feasible")
STOCHASTIC = {"drift", "holes", "video3dgs"}


def _prepare(path):
    from wanderland_nav.preparation.scene import prepare_scene

    return prepare_scene(path)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--scene", type=Path, default=None, help="a grounded scene folder (default: the demo block)")
    ap.add_argument("--kitti", type=Path, default=None,
                    help="the real KITTI street (LiDAR-only) as the grounded scene: the folder kitti_street.py builds")
    ap.add_argument("--preset", default="tiny", help="demo preset when --scene is not given")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    from planners import NavMesh
    from wanderland_nav.degrade import PRESETS, build_degraded_scene, preset
    from wanderland_nav.degrade.report import degradation_report
    from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
    from wanderland_nav.episodes.schema import load_episodes
    from wanderland_nav.scene import load_scene, make_demo_scene

    src = args.scene
    if args.kitti:
        if not (args.kitti / "lidar" / "poses.txt").is_file():
            raise SystemExit(f"{args.kitti}: no lidar/poses.txt; build the street first: "
                             f"python experiments/real_streets/kitti_street.py --scene {args.kitti}")
        src = args.kitti
    src = src or make_demo_scene(args.out / f"demo_{args.preset}", seed=0, preset=args.preset)
    grounded = _prepare(src)
    ep_path = args.out / "grounded_episodes.json"
    if not ep_path.is_file():
        write_scene_episodes(grounded, NavMesh.load(grounded.navmesh_path), ep_path, num_episodes=args.episodes,
                             seed=0, settings=GeneratorSettings(goal_images=False))
    episodes = load_episodes(ep_path)
    not_applicable: dict[str, str] = {}
    rows = {"grounded": [degradation_report(grounded, grounded, episodes=episodes, samples=args.samples)]}
    for name in PRESETS:
        for seed in (args.seeds if name in STOCHASTIC else args.seeds[:1]):
            t0 = time.perf_counter()
            try:
                out = build_degraded_scene(src, args.out / f"{name}_s{seed}", preset(name, seed))
            except ValueError as e:
                if "not applicable" not in str(e):
                    raise
                print(f"{name}: {e}", flush=True)
                not_applicable[name] = str(e).split(": ", 1)[-1]
                break
            row = degradation_report(grounded, _prepare(out), episodes=episodes, samples=args.samples)
            row["build_s"] = time.perf_counter() - t0
            rows.setdefault(name, []).append(row)
            print(json.dumps({"preset": name, "seed": seed, **row}), flush=True)
    (args.out / "geometry_rows.json").write_text(json.dumps(rows, indent=1))
    print(f"\nscene: {load_scene(src).name}, {len(episodes)} grounded expert episodes, seeds {args.seeds}")
    # a scene without a GT mesh (KITTI) has no vs_gt_mesh figures: those columns are left out
    columns = [c for c in COLUMNS if c == "feasible" or any(c in r for rs in rows.values() for r in rs)]
    print("| environment | n | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 2) + "|")
    for name, rs in rows.items():
        cells = []
        for c in columns:
            v = np.array([r["episodes_feasible"] / r["episodes"] if c == "feasible" else r.get(c, np.nan)
                          for r in rs], float)
            cells.append(f"{v.mean():.3g}" + (f" [{v.min():.3g}, {v.max():.3g}]" if len(v) > 1 else ""))
        print(f"| {name} | {len(rs)} | " + " | ".join(cells) + " |")
    for name, why in not_applicable.items():
        print(f"| {name} | 0 | not applicable: {why} |" + " |" * (len(columns) - 1))


if __name__ == "__main__":
    main()
