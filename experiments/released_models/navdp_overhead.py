"""NavDP's contract vs in process: per-step CPU time at B = 8, 96 px, and what JPEG coding does to an image policy.

    python -m experiments.released_models.navdp_overhead [--steps 20] [--batch 8] [--size 96]

Two policies, each called for `--steps` steps on the same inputs, in process (`NavPolicyAsExternal.act` on the
frame history) and through NavDP's contract (`NavDPPolicy` -> HTTP on localhost -> `NavDPServer`, which decodes
the JPEG / PNG, keeps the history and calls the same policy), both in this process so `time.process_time`
counts the client, the server thread and the policy together, one intra-op thread:

* the released NoMaD (seeded stand-in weights, `policies.released.random_weights`; 4 frames + the goal view at 96 x 96; its forward is the realistic cost);
* the straight-line `GoalVectorPolicy` (no image: the contract's own cost per step, in milliseconds).

For NoMaD it also prints the largest waypoint difference between the two paths (the JPEG effect; the goal view
and every frame cross as JPEG at quality 95) and the mean absolute pixel error of the coded frames.
"""

from __future__ import annotations

import argparse
import threading
import time

import numpy as np
import torch

from policies import make_policy
from policies.released.random_weights import seeded_state_dict
from wanderland_nav import keys
from wanderland_nav.external.actor import NavPolicyAsExternal
from wanderland_nav.external.examples import GoalVectorPolicy
from wanderland_nav.external.navdp import NavDPPolicy, NavDPServer, decode_rgb, encode_rgb
from wanderland_nav.external.protocol import NEW_EPISODE


def frames(steps: int, b: int, size: int, seed: int = 0) -> np.ndarray:
    """uint8 `[steps, B, size, size, 3]`: smooth colour fields drifting per step (image-like, not noise)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    out = np.empty((steps, b, size, size, 3), np.uint8)
    phase = rng.uniform(0, 2 * np.pi, (b, 3, 2))
    for t in range(steps):
        for c in range(3):
            f = 0.5 + 0.5 * np.sin(6 * xx[None] + phase[:, c, :1, None] + 0.2 * t) * np.cos(4 * yy[None] + phase[:, c, 1:, None])
            out[t, :, :, :, c] = np.clip(f * 255 + rng.normal(0, 4, f.shape), 0, 255)
    return out


def timed(fn, steps: int) -> tuple[float, list]:
    outs = []
    t0 = time.process_time()
    for t in range(steps):
        outs.append(fn(t))
    return (time.process_time() - t0) / steps, outs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--size", type=int, default=96)
    a = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    b, steps, size = a.batch, a.steps, a.size
    rgb = frames(steps + 3, b, size)
    goal_view = frames(1, b, size, seed=1)[0]
    depth = np.full((b, 1, size, size, 1), 3.0, np.float32)
    goal_vec = np.tile(np.array([[4.0, 1.0]], np.float32), (b, 1))

    released = make_policy("released", model="nomad", stop_distance=-1e9)
    released.net.load_state_dict(seeded_state_dict(released.net, 46))  # the parity fixtures' fan-in-scaled fill
    nomad = NavPolicyAsExternal(released)
    straight = GoalVectorPolicy(num_waypoints=8)
    rows = []
    for name, policy, goal in (("nomad (released, seeded stand-in weights)", nomad, "image"), ("straight (no image)", straight, "point")):
        c = policy.context

        def local(t, policy=policy, c=c):
            hist = rgb[[max(i, 0) for i in range(t - c + 1, t + 1)]]  # [C, B, H, W, 3], the first repeated
            obs = {keys.RGB: hist.transpose(1, 0, 2, 3, 4), keys.GOAL_IMAGE: goal_view, keys.GOAL_VECTOR: goal_vec,
                   keys.HAS_GOAL_IMAGE: np.ones((b, 1), bool), NEW_EPISODE: np.full(b, t == 0)}
            return np.asarray(policy.act({k: v for k, v in obs.items() if k in policy.observes or k == NEW_EPISODE}))

        server = NavDPServer(policy)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        client = NavDPPolicy(server.url, goal=goal, num_waypoints=policy.num_waypoints)

        def remote(t):
            return client.act({keys.RGB: rgb[t][:, None], keys.DEPTH: depth, keys.GOAL_IMAGE: goal_view,
                               keys.GOAL_VECTOR: goal_vec, NEW_EPISODE: np.full(b, t == 0)})

        local(0), remote(0)  # warm-up: first calls allocate
        client.close()
        client = NavDPPolicy(server.url, goal=goal, num_waypoints=policy.num_waypoints)
        t_local, out_local = timed(local, steps)
        t_remote, out_remote = timed(remote, steps)
        server.shutdown()
        server.server_close()
        err = np.abs(np.stack(out_local) - np.stack(out_remote))
        diff = (float(err.max()), float(err.mean()))
        rows.append((name, t_local, t_remote, diff))
    pix = float(np.abs(decode_rgb(encode_rgb(rgb[0]), b).astype(int) - rgb[0]).mean())
    print(f"B = {b}, {size} x {size} px, {steps} steps, CPU time per step (time.process_time, 1 thread)")
    print("| policy | in process (ms) | NavDP contract (ms) | overhead (ms) | ratio | waypoint difference max / mean (m) |")
    print("|---|---|---|---|---|---|")
    for name, tl, tr, (dmax, dmean) in rows:
        ratio = f"{tr / tl:.2f}x" if tl > 0 else "-"
        print(f"| {name} | {tl * 1e3:.1f} | {tr * 1e3:.1f} | {(tr - tl) * 1e3:+.1f} | {ratio} | {dmax:.4f} / {dmean:.4f} |")
    print(f"JPEG (quality 95) mean absolute pixel error of the frames: {pix:.2f} / 255")


if __name__ == "__main__":
    main()
