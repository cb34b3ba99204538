"""The grounding study's worlds seen from above: each world's navmesh, and the grounded test routes that survive
in it (mapped into its frame, `grounding_study/routes.py`), side by side in one PNG.

    python experiments/geometry_grounding/worlds_png.py <the study's out> --png worlds.png

The grounded world is the study's source scene (read from a train cell's config); each degraded world is
`<out>/scenes/<preset>_s<k>`, its routes file `<out>/routes/routes_<preset>_s<k>_*.json`. Every panel is in its
own world's nav frame (x, y on its ground plane) at the same metric scale, so a scale error shows as a smaller or
larger map; its title gives the walkable area, the navmesh's islands and how many grounded routes it kept, and
the same figures are printed as a markdown table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from planners import NavMesh
from wanderland_nav.atomic import atomic_path
from wanderland_nav.episodes.schema import load_episodes
from wanderland_nav.grounding_study.plan import MANIFEST
from wanderland_nav.scene.loader import load_scene
from wanderland_nav.viz.topdown import navmesh_triangles_nav


def grounded_source(out: Path) -> tuple[Path, Path]:
    """(grounded scene folder, its episodes file) from a done train cell of the grounded world."""
    manifest = json.loads((out / MANIFEST).read_text())
    for key, entry in manifest.items():
        if key.startswith("eval/grounded/") and entry.get("status") == "done":
            result = json.loads((Path(entry["dir"]) / "result.json").read_text())
            episodes = Path(result["episodes_file"])
            return episodes.parent, episodes
    raise SystemExit(f"{out / MANIFEST}: no evaluation in the grounded world is done yet")


def _routes(path: Path | None, split: str = "test") -> list[np.ndarray]:
    """Scene-frame expert paths `[P, 3]` of an episodes file's `split` (none without a file)."""
    if path is None or not path.exists():
        return []
    return [np.asarray(e.reference_path, dtype=np.float64) for e in load_episodes(path, split=split)]


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the study's out folder")
    ap.add_argument("--png", type=Path, required=True)
    ap.add_argument("--routes", type=int, default=40, help="routes drawn per panel (the first ones)")
    a = ap.parse_args(argv)
    source, episodes = grounded_source(a.out)
    worlds = [("grounded", source, episodes)]
    for folder in sorted((a.out / "scenes").glob("*_s*")):
        files = sorted((a.out / "routes").glob(f"routes_{folder.name}_*.json"))
        worlds.append((folder.name.rsplit("_s", 1)[0], folder, files[-1] if files else None))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    panels = []
    for name, folder, routes_file in worlds:
        scene = load_scene(folder)
        R = np.asarray(scene.nav_from_scene, dtype=np.float64)
        nav = NavMesh.load(folder / "navmesh.npz")
        tri = navmesh_triangles_nav(nav, R)
        paths = [p @ R.T for p in _routes(routes_file)]
        panels.append((name, tri, paths, nav.area, len(nav.islands), len(paths)))
    lo = np.min([t[:, :, :2].reshape(-1, 2).min(0) for _, t, *_ in panels if t is not None and len(t)], axis=0)
    hi = np.max([t[:, :, :2].reshape(-1, 2).max(0) for _, t, *_ in panels if t is not None and len(t)], axis=0)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.6), squeeze=False)
    for ax, (name, tri, paths, area, islands, kept) in zip(axes[0], panels):
        if tri is not None and len(tri):
            ax.add_collection(PolyCollection(tri[:, :, :2], facecolors="0.8", edgecolors="none"))
        for p in paths[: a.routes]:
            ax.plot(p[:, 0], p[:, 1], "-", lw=0.8, alpha=0.8)
        routes = "test routes" if name == "grounded" else "grounded test routes kept"
        ax.set_title(f"{name}\n{area:,.0f} m² walkable, {islands} islands\n{kept} {routes}", fontsize=9)
        ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
    fig.suptitle(f"{a.out.name}: the worlds' navmeshes (nav frame, metres)", fontsize=10)
    fig.tight_layout()
    with atomic_path(a.png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    print("| world | walkable m² | navmesh islands | grounded test routes there |\n|---|---|---|---|")
    for name, _, _, area, islands, kept in panels:
        print(f"| {name} | {area:,.0f} | {islands} | {kept} |")
    print(a.png)
    return a.png


if __name__ == "__main__":
    main()
