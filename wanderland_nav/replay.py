"""Replay a rollout or expert paths into a rerun recording.

    python -m wanderland_nav.replay rollout=<file> out=<file.rrd>

* `rollout=<file.npz>` (from `evaluate ... save_rollouts=<file.npz>`): the scene (collision mesh,
  navmesh by island, points, capture cameras), the episodes the agents ran, and per step each agent's
  pose, camera image, predicted waypoints, reward, distance to goal and finished-episode metrics.
  Frames not stored in the file are re-rendered from the scene's splats with the recorded camera.
* `episodes=<episodes.json>`: the scene and the episodes, and the expert's camera rendered along
  each `gt_locations` path (one agent playing the episodes one after another).
* `viewer=true` opens the rerun viewer on the result when one is available.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

import sys
import time
from pathlib import Path

from omegaconf import DictConfig

from wanderland_nav.compose import typed_config
from wanderland_nav.compose.cli import quote_overrides
from wanderland_nav.compose.replaying import replay_frames, replay_inputs
from wanderland_nav.compose.schema import ReplayConfig
from wanderland_nav.viz.recording import open_viewer, write_recording


def run(cfg: DictConfig) -> dict:
    """Everything `main` does, callable with a composed config (tests). Returns the logged counts + `out`."""
    t0 = time.perf_counter()
    c: ReplayConfig = typed_config(cfg, ReplayConfig)
    rollout, scene, episodes, src = replay_inputs(c)
    frames = replay_frames(c, rollout, scene)
    out = Path(c.out) if c.out is not None else src.with_suffix(".rrd")
    counts = write_recording(out, scene=scene, rollout=rollout, episodes=episodes, frames=frames, agents=c.agents,
                             max_points=c.max_points, max_cameras=c.max_cameras, frame_chunk=c.frame_chunk)
    print(f"wrote {out} ({rollout.num_steps} steps x {rollout.num_agents} agents, {len(episodes)} episodes, "
          f"{time.perf_counter() - t0:.1f}s)")
    if c.viewer:
        open_viewer(out)
    return {**counts, "out": str(out)}


def replay_overrides(argv: list[str]) -> list[str]:
    """The overrides quoted for Hydra (`quote_overrides`); `scene=` is refused with the way out (Hydra's own
    message names none): a rollout records its own scene."""
    if any(a.startswith("scene=") for a in argv):
        sys.exit("replay takes rollout=<file.npz> or episodes=<episodes.json> [scene_path=<scene folder>], not "
                 "scene=: a rollout records its own scene (over a scene set, replay one scene's file at a time)")
    return quote_overrides(argv)


main = entry_point("replay", run, argv=replay_overrides)


if __name__ == "__main__":
    main()
