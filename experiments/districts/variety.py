"""Variety over district seeds: what each seed's layout, navmesh and episodes come to.

    python experiments/districts/variety.py --seeds 0-19 --root /tmp/districts --episodes 100 --out experiments/districts/variety.json

Per seed: build the small district (seconds of CPU), prepare it with the default navigation (collision mesh +
navmesh), draw `--episodes` expert episodes in the district's regime without goal views, and report the
extent, the street graph (nodes, edges, degree sequence), block kinds, navigable area, islands, the
navmesh's elevation range, the navigable area inside buildings, and the episodes' geodesic lengths,
labels and elevation changes. Ends with the distribution over seeds and the number of distinct street graphs.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np
import torch


def seeds_arg(s: str) -> list[int]:
    out = []
    for part in s.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def one(root: Path, seed: int, n_episodes: int) -> dict:
    from planners import NavMesh
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config
    from wanderland_nav.episodes.generate import GeneratorSettings, generate_episodes
    from wanderland_nav.scene.district import make_district
    from wanderland_nav.preparation.scene import prepare_scene

    t0 = time.process_time()
    path = make_district(root / f"s{seed}_small", seed=seed, size="small")
    t_build = time.process_time() - t0
    nav = typed_config(compose_config("prepare", []), PrepareConfig).navigation
    t0 = time.process_time()
    scene = prepare_scene(path, collision=nav.collision, navmesh=nav.navmesh)
    t_prep = time.process_time() - t0
    nm = NavMesh.load(scene.navmesh_path)
    meta = json.loads((path / "scene_meta.json").read_text())
    d = meta["generator"]["district"]
    R = scene.nav_from_scene
    local = np.concatenate([nm.verts_xy, nm.verts_z[:, None]], -1)
    v_scene = nm.to_scene(torch.as_tensor(local, dtype=torch.float64)).numpy()
    tri = np.asarray(nm.tris)
    a, b, c = v_scene[tri[:, 0]] @ R.T, v_scene[tri[:, 1]] @ R.T, v_scene[tri[:, 2]] @ R.T
    area = 0.5 * np.abs(np.cross(b[:, :2] - a[:, :2], c[:, :2] - a[:, :2]))
    centroid_scene = (v_scene[tri[:, 0]] + v_scene[tri[:, 1]] + v_scene[tri[:, 2]]) / 3.0
    indoor_area = float(area[scene.is_indoor(centroid_scene)].sum())
    isl = sorted(nm.islands, key=lambda i: -i.area)
    t0 = time.process_time()
    eps, summary = generate_episodes(scene, nm, num_episodes=n_episodes, seed=0,
                                     settings=GeneratorSettings(goal_images=False))
    t_eps = time.process_time() - t0
    geo = np.array([e.geodesic_distance for e in eps])
    labels = Counter(e.extras["environment"] for e in eps)
    elev = np.array([e.extras["elevation_change"] for e in eps])
    deg = Counter(k for e in d["street_graph"]["edges"] for k in e[:2])
    return {
        "seed": seed, "extent_m": d["extent_m"], "area_m2": d["area_m2"],
        "streets": len(d["streets"]), "pedestrian_streets": sum(s["kind"] == "pedestrian" for s in d["streets"]),
        "graph_nodes": len(d["street_graph"]["nodes"]), "graph_edges": len(d["street_graph"]["edges"]),
        "degrees": sorted(deg.values(), reverse=True),
        "graph_key": json.dumps(sorted(sorted([d["street_graph"]["nodes"][x], d["street_graph"]["nodes"][y]]) + [k]
                                       for x, y, k in d["street_graph"]["edges"])),
        "blocks": [bl["kind"] for bl in d["blocks"]],
        "navigable_m2": round(nm.area, 1), "islands": len(isl), "largest_island_share": round(isl[0].area / nm.area, 4),
        "navmesh_elevation_m": round(float(np.ptp(np.concatenate([a[:, 2], b[:, 2], c[:, 2]]))), 3),
        "indoor_navigable_m2": round(indoor_area, 1), "gaussians": meta["generator"]["counts"]["gaussians"],
        "lidar_points": meta["generator"]["counts"]["lidar_points"], "images": meta["generator"]["counts"]["images"],
        "episodes": len(eps), "geodesic_m": {"median": round(float(np.median(geo)), 1),
                                             "p90": round(float(np.percentile(geo, 90)), 1),
                                             "max": round(float(geo.max()), 1), "min": round(float(geo.min()), 1)},
        "routes_over_100m": int((geo >= 100).sum()), "labels": dict(labels),
        "routes_changing_level": int((elev >= 0.5).sum()),
        "cpu_s": {"build": round(t_build, 1), "prepare": round(t_prep, 1), "episodes": round(t_eps, 1)},
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=seeds_arg, default=seeds_arg("0-19"))
    ap.add_argument("--root", type=Path, default=Path("/tmp/districts"))
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--out", type=Path, default=Path("experiments/districts/variety.json"))
    a = ap.parse_args()
    torch.set_num_threads(1)
    rows = json.loads(a.out.read_text()) if a.out.is_file() else []
    done = {r["seed"] for r in rows}
    for s in a.seeds:
        if s in done:
            continue
        r = one(a.root, s, a.episodes)
        rows.append(r)
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(rows, indent=1))
        print(f"seed {s}: {r['extent_m'][0]:.0f} x {r['extent_m'][1]:.0f} m, {r['graph_edges']} street segments, "
              f"navigable {r['navigable_m2']:.0f} m2 ({r['islands']} islands, largest {r['largest_island_share']:.3f}), "
              f"elevation {r['navmesh_elevation_m']:.2f} m, indoor {r['indoor_navigable_m2']:.0f} m2, routes median "
              f"{r['geodesic_m']['median']} max {r['geodesic_m']['max']} m, labels {r['labels']}, "
              f"cpu {r['cpu_s']}", flush=True)
    rows = [r for r in rows if r["seed"] in set(a.seeds)]

    def dist(vals):
        v = np.asarray(vals, dtype=np.float64)
        return f"min {v.min():.1f} / median {np.median(v):.1f} / max {v.max():.1f}"

    print(f"\n{len(rows)} seeds")
    print("area m2:", dist([r["area_m2"] for r in rows]))
    print("navigable m2:", dist([r["navigable_m2"] for r in rows]))
    print("islands:", dict(Counter(r["islands"] for r in rows)), "largest island share:",
          dist([100 * r["largest_island_share"] for r in rows]), "%")
    print("navmesh elevation m:", dist([r["navmesh_elevation_m"] for r in rows]))
    print("indoor navigable m2:", dist([r["indoor_navigable_m2"] for r in rows]))
    print("route median m:", dist([r["geodesic_m"]["median"] for r in rows]),
          "| route max m:", dist([r["geodesic_m"]["max"] for r in rows]))
    tot = Counter()
    for r in rows:
        tot.update(r["labels"])
    n = sum(r["episodes"] for r in rows)
    print("episode labels:", {k: f"{v} ({v / n:.1%})" for k, v in tot.items()}, "of", n)
    print("routes >= 100 m:", sum(r["routes_over_100m"] for r in rows), "| changing level (>= 0.5 m):",
          sum(r["routes_changing_level"] for r in rows))
    print("distinct street graphs:", len({r["graph_key"] for r in rows}), "of", len(rows),
          "| distinct degree sequences:", len({tuple(r["degrees"]) for r in rows}))
    print("block kinds:", dict(Counter(k for r in rows for k in r["blocks"])))


if __name__ == "__main__":
    main()
