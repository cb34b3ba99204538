"""What JPEG coding does to an image policy's episodes: the released NoMaD in process vs behind NavDP's contract.

    python -m experiments.released_models.navdp_records <weights folder> [--episodes 8]

The folder holds `nomad.pth` (e.g. from `experiments.released_models.stand_in_weights`). The same policy
(its stop rule off, so the agents move) runs on the image-goal task of the tiny demo twice: in process
(`{model: nomad, ...}`) and served by `NavDPServer` in a thread of this process, reached through
`{navdp_url: ...}` (its frames and goal views cross as JPEG, quality 95). Same camera (96 x 96), episodes,
seed. Prints the benchmark table and the per-episode differences of the final distance to the goal.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
from pathlib import Path

import numpy as np

from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config
from wanderland_nav.compose.policy_sources import released_policy
from wanderland_nav.external.actor import NavPolicyAsExternal
from wanderland_nav.external.navdp import NavDPServer


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("weights")
    ap.add_argument("--episodes", type=int, default=8)
    a = ap.parse_args()
    weights = str(Path(a.weights) / "nomad.pth")
    spec = {"model": "nomad", "weights": weights, "stop_distance": -1e9}
    server = NavDPServer(NavPolicyAsExternal(released_policy(spec)[0]))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with tempfile.TemporaryDirectory() as out:
            pol = (f"[{{name: in_process, model: nomad, weights: '{weights}', stop_distance: -1e9}}, "
                   f"{{name: via_navdp, navdp_url: '{server.url}', navdp_goal: image, num_waypoints: 8, "
                   f"image_size: [96, 96]}}]")
            res = run(compose_config("benchmark", ["scene=demo", "scene.preset=tiny", f"num_episodes={a.episodes}",
                                                   "batch_size=8", "env.termination.max_steps=60", f"out={out}",
                                                   "progress=false", "tasks=[imagegoal]", f"policies={pol}"]))
    finally:
        server.shutdown()
        server.server_close()
    ours, via = res["results"][("imagegoal", "in_process")], res["results"][("imagegoal", "via_navdp")]
    d = np.array([v["distance_to_goal"] - o["distance_to_goal"] for o, v in zip(ours, via)])
    print(res["table"])
    print(f"final distance to goal, via NavDP - in process, per episode (m): {np.round(d, 3).tolist()}")
    print(f"mean |difference| {np.abs(d).mean():.3f} m, max {np.abs(d).max():.3f} m, "
          f"success agreement {sum(o['success'] == v['success'] for o, v in zip(ours, via))} / {len(d)}")


if __name__ == "__main__":
    main()
