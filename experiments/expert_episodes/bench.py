"""Episodes per second of the expert generator on the demo scene.

    python experiments/expert_episodes/bench.py [--scene data/scenes/demo] [--preset default] [--n 200]

Prints one line per configuration: sampling + paths + instructions only, then with goal images.
Timings include everything `generate_episodes` does (not scene preparation, which is cached).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch

from planners import NavMesh
from wanderland_nav.episodes.generate import GeneratorSettings, generate_episodes
from wanderland_nav.preparation.scene import ensure_demo_scene


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="data/scenes/demo")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--n-images", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    t = time.perf_counter()
    scene = ensure_demo_scene(args.scene, seed=0, preset=args.preset)
    print(f"scene {scene.name} ({args.preset}) ready in {time.perf_counter() - t:.1f}s: "
          f"{len(scene.cameras)} cameras, {len(scene.points)} points")
    navmesh = NavMesh.load(scene.navmesh_path)

    no_img = GeneratorSettings(goal_images=False)
    generate_episodes(scene, navmesh, num_episodes=5, seed=args.seed + 1, settings=no_img)  # warm-up
    eps, s = generate_episodes(scene, navmesh, num_episodes=args.n, seed=args.seed, settings=no_img)
    print(f"episodes (no goal images): {s.kept}/{args.n} in {s.seconds:.2f}s -> {s.episodes_per_second:.1f} episodes/s "
          f"({s.candidates} candidate pairs, {s.candidates / s.seconds:.0f} pairs/s)")
    print("  " + s.format().splitlines()[1].strip())
    print("  " + s.format().splitlines()[2].strip())

    with tempfile.TemporaryDirectory() as d:
        eps, s = generate_episodes(scene, navmesh, num_episodes=args.n_images, seed=args.seed,
                                   settings=GeneratorSettings(), goal_image_dir=Path(d) / "goal_images")
        print(f"episodes with 320x240 goal images (cpu): {s.kept} in {s.seconds:.2f}s "
              f"-> {s.episodes_per_second:.2f} episodes/s")


if __name__ == "__main__":
    main()
