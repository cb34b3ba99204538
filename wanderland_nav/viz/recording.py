"""Write one replay recording (`.rrd`): scene, episodes and a rollout, with the default blueprint.

Used by `python -m wanderland_nav.replay`; separate from the entry point so tests and notebooks can
call it with typed arguments. The file is written beside its target and renamed into place once
rerun has flushed it, so an interrupted replay never leaves a half-written `.rrd`.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import rerun as rr

from wanderland_nav.atomic import atomic_path
from wanderland_nav.evaluation.rollouts import Rollout
from wanderland_nav.viz.blueprint import default_blueprint
from wanderland_nav.viz.rerun_episodes import log_episodes
from wanderland_nav.viz.rerun_rollout import FrameSource, log_rollout
from wanderland_nav.viz.rerun_scene import log_scene


def write_recording(out: str | Path, *, scene=None, rollout: Rollout | None = None, episodes=None,
                    frames: FrameSource | None = None, agents: list[int] | None = None, navmesh=None,
                    max_points: int = 50_000, max_cameras: int = 32, application_id: str = "wanderland_nav",
                    recording_id: str | None = None, frame_chunk: int = 64) -> dict:
    """Log what is given into `out` and return counts of what was logged."""
    out = Path(out)
    if out.suffix != ".rrd":
        raise ValueError(f"out={out}: recordings end in .rrd")
    counts: dict = {}
    with atomic_path(out) as tmp:
        rec = rr.RecordingStream(application_id, recording_id=recording_id or out.stem)
        rec.save(str(tmp), default_blueprint=default_blueprint(camera=rollout is not None))
        try:
            if scene is not None:
                counts["scene"] = log_scene(rec, scene, navmesh=navmesh, max_points=max_points,
                                            max_cameras=max_cameras)
            if episodes:
                up = scene.up_axis if scene is not None else (rollout.meta.up_axis if rollout is not None else "+z")
                counts["episodes"] = log_episodes(rec, episodes, up)
            if rollout is not None:
                counts["rollout"] = log_rollout(rec, rollout, frames=frames, agents=agents, frame_chunk=frame_chunk)
        finally:
            rec.flush()
            rec.disconnect()  # footer written, file complete before the rename
    return counts


def open_viewer(path: str | Path) -> bool:
    """Start the rerun viewer on `path` in the background when one can run; False (with a message) if not.

    Headless machines (no DISPLAY / WAYLAND_DISPLAY on Linux) get the command to run elsewhere instead of
    a viewer process that dies on start.
    """
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        print(f"no display for the viewer; open the recording where there is one: rerun {path}")
        return False
    exe = shutil.which("rerun")
    cmd = [exe, str(path)] if exe else [sys.executable, "-m", "rerun", str(path)]
    try:
        subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        return True
    except OSError as e:
        print(f"viewer not available ({e}); open the recording with: rerun {path}")
        return False
