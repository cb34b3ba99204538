"""The expert's success on an episode set: the ceiling of imitation learning on it.

    OMP_NUM_THREADS=1 python experiments/env/expert_success.py --scene data/scenes/demo \
        --episodes data/scenes/demo/episodes.json [--batch 32] [--split test]

Camera off, the expert following each episode's reference path (as `python -m wanderland_nav.evaluate
reference=expert`, at a larger batch: agents do not interact, so the batch size changes no episode).
Prints NE / SR / SPL / IR and the failed episodes with their collisions and where they ended.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import torch


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, required=True)
    ap.add_argument("--episodes", type=Path, required=True)
    ap.add_argument("--split", default=None)
    ap.add_argument("--batch", type=int, default=32)
    args = ap.parse_args()
    torch.set_num_threads(1)
    from planners import NavMesh
    from wanderland_nav.envs import ExpertPolicy, NavEnvConfig
    from wanderland_nav.evaluation.loop import run_evaluation
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene.loader import load_scene

    scene = load_scene(args.scene)
    episodes = load_episodes(args.episodes, split=args.split)
    cfg = NavEnvConfig()
    cfg.camera.enabled = False
    cfg.goal_image = "none"
    t0 = time.process_time()
    env = make_nav_env(scene, episodes, NavMesh.load(scene.navmesh_path), config=cfg, batch_size=args.batch, seed=0)
    res = run_evaluation(env, ExpertPolicy(env), name="expert")
    print(f"{len(episodes)} episodes, batch {args.batch}, {time.process_time() - t0:.1f} CPU-s, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(res.table)
    for row in res.records:
        if not bool(row["success"]):
            print(f"  failed: episode {row['episode_index']} (id {row.get('episode_id')}), collisions "
                  f"{row['collisions']}, intervention {bool(row['intervention'])}, NE {float(row['navigation_error']):.2f} m")

if __name__ == "__main__":
    main()
