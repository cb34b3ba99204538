"""Three district seeds side by side: the navmesh from above (coloured by height), the street graph (dashed:
red roads, blue pedestrian streets), the capture cameras (white: training loops, red: the extrapolation paths
along the streets), the indoor regions (orange) and, under each map, the view of the capture camera marked
with a star.

    python experiments/districts/figure.py --seeds 0 1 2 --root data/scenes/district --out docs/guide/img/districts.png

Each district is built (size small) and prepared with the default navigation if it is not already.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from PIL import Image  # noqa: E402

from planners import NavMesh  # noqa: E402
from wanderland_nav.scene.district import make_district  # noqa: E402


def prepared(root: Path, seed: int):
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config
    from wanderland_nav.preparation.scene import prepare_scene

    path = make_district(root / f"s{seed}_small", seed=seed, size="small")
    nav = typed_config(compose_config("prepare", []), PrepareConfig).navigation
    return prepare_scene(path, collision=nav.collision, navmesh=nav.navmesh)


def draw(ax_map, ax_view, scene, seed: int, view_index: int) -> None:
    nm = NavMesh.load(scene.navmesh_path)
    R = scene.nav_from_scene
    import torch

    local = np.concatenate([nm.verts_xy, nm.verts_z[:, None]], -1)
    v = nm.to_scene(torch.as_tensor(local, dtype=torch.float64)).numpy() @ R.T  # nav frame
    tris = np.asarray(nm.tris)
    z = v[tris][:, :, 2].mean(1)
    pc = PolyCollection(v[tris][:, :, :2], array=z, cmap="viridis", edgecolors="none", clim=(0.0, 4.0))
    ax_map.add_collection(pc)
    cams = scene.capture_positions() @ R.T
    split = np.array([c.split for c in scene.cameras])
    ax_map.scatter(*cams[split == "train", :2].T, s=0.6, c="white", lw=0)
    ax_map.scatter(*cams[split == "val", :2].T, s=0.6, c="red", lw=0)
    for reg in scene.indoor_regions:
        p = np.asarray(reg["polygon_xy"] + reg["polygon_xy"][:1])
        ax_map.plot(p[:, 0], p[:, 1], color="orange", lw=1.0)
    cam = scene.cameras[view_index]
    c = cam.world_from_cam[:3, 3] @ R.T
    ax_map.plot([c[0]], [c[1]], marker="*", color="magenta", ms=9)
    graph = scene.meta["generator"]["district"]["street_graph"]
    nodes = np.asarray(graph["nodes"])
    for a, b, kind in graph["edges"]:
        ax_map.plot(nodes[[a, b], 0], nodes[[a, b], 1], color="#ff9090" if kind == "road" else "#90c0ff", lw=0.8, ls="--")
    isl = sorted(nm.islands, key=lambda i: -i.area)
    ax_map.set_title(f"seed {seed}: {nm.area:.0f} m$^2$ walkable, {len(isl)} island(s), {len(graph['edges'])} street "
                     "segments", fontsize=9)
    ax_map.set_aspect("equal")
    ax_map.autoscale_view()
    ax_map.set_xticks([])
    ax_map.set_yticks([])
    ax_map.set_facecolor("#303030")
    ax_view.imshow(Image.open(scene.root / "images" / cam.name) if (scene.root / "images" / cam.name).is_file()
                   else Image.open(cam.image_path))
    ax_view.set_axis_off()
    ax_view.set_title(f"capture view {cam.name}", fontsize=8)
    return pc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--root", type=Path, default=Path("data/scenes/district"))
    ap.add_argument("--out", type=Path, default=Path("docs/guide/img/districts.png"))
    ap.add_argument("--view", type=int, default=40, help="index of the capture camera shown under each map")
    a = ap.parse_args()
    n = len(a.seeds)
    fig, axes = plt.subplots(2, n, figsize=(4.4 * n, 7.2), gridspec_kw={"height_ratios": [1.0, 1.0]}, layout="constrained")
    axes = np.asarray(axes).reshape(2, n)
    pc = None
    for k, seed in enumerate(a.seeds):
        pc = draw(axes[0, k], axes[1, k], prepared(a.root, seed), seed, a.view)
    fig.colorbar(pc, ax=list(axes[0]), shrink=0.7, label="navmesh height (m)")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=110)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
