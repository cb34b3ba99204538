"""`RerunLogger`: the trainer's logger protocol (`wanderland_nav.rl.loggers.Logger`) writing a rerun
recording: scalar curves (losses, train stats, eval NE/SR/SPL/IR) and, every `rollout_every`-th
`log_rollout` call per tag, a few agents' rollouts with their camera frames.

Selected with `logger=rerun` (`conf/logger/rerun.yaml`); training defaults to the console logger.
One recording per run: `<run_dir>/rerun.rrd` (application id `wanderland_nav`, recording id = the
run folder name). A resumed run rewrites the file: the earlier run's scalars are read back first and
logged again up to the checkpoint it resumes from (`truncate`), so each step holds one value; the
earlier run's rollouts are not carried over.

Cost (why the defaults): scalars are a few microseconds each; a rollout costs one batched call per
entity and its frames' bytes, so it is throttled by `rollout_every` and `max_agents`. The file is
streamed as the run goes (a killed run leaves a readable, footer-less recording).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable

import numpy as np
import rerun as rr

from wanderland_nav.evaluation.recording import rollout_from_tensordict
from wanderland_nav.evaluation.rollouts import Rollout
from wanderland_nav.viz.blueprint import default_blueprint
from wanderland_nav.viz.rerun_rollout import log_rollout
from wanderland_nav.viz.rerun_scene import log_scene


class RerunLogger:
    """Logger protocol over a rerun `RecordingStream`.

    out_dir: where `rerun.rrd` is written (None: no file; use `spawn=True` for a live viewer).
    rollout_every: per tag, log the 1st, (n+1)-th, (2n+1)-th ... `log_rollout` call (0: never). Each eval
        phase has its own tag (logged); PPO hands over every collected batch as `train` (every n-th logged).
    max_agents: agents of a rollout to show (their frames dominate the recording's size).
    spawn: also stream to a viewer (spawned if none is running; ignored when none can be started).
    scene: the loaded `Scene` (from the caller), logged once with the first scene-frame rollout (point
        subsample, collision mesh, navmesh, camera frustums) as context; None: rollouts only.
    """

    def __init__(self, out_dir: str | Path | None, *, rollout_every: int = 5, max_agents: int = 2,
                 spawn: bool = False, application_id: str = "wanderland_nav", recording_id: str | None = None,
                 file_name: str = "rerun.rrd", scene=None):
        self.path = Path(out_dir) / file_name if out_dir is not None else None
        rid = recording_id or (Path(out_dir).resolve().name if out_dir is not None else "run")
        # an earlier run's scalars, read before save() overwrites the file; logged again by truncate()
        self._earlier = scalar_rows(self.path) if self.path is not None and self.path.is_file() else None
        self.rec = rr.RecordingStream(application_id, recording_id=rid)
        bp = default_blueprint(training=True, camera=False, plots=False)  # rollouts sit under world/rollouts/<tag>
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(str(self.path), default_blueprint=bp)
        if spawn:
            try:
                self.rec.spawn(connect=self.path is None, default_blueprint=bp)
            except Exception as e:  # no viewer binary / no display: keep writing the file
                print(f"RerunLogger: could not spawn a viewer ({e}); writing {self.path}")
        self.rollout_every, self.max_agents = int(rollout_every), int(max_agents)
        self._rollout_calls: dict[str, int] = {}
        self._scene = scene  # a loaded Scene from the caller (never read from disk here), or None
        self._meta = None  # the last Rollout's meta (frames, camera), reused for TensorDict rollouts
        self.rollouts_logged = 0

    @property
    def wants_rollouts(self) -> bool:
        """Whether the trainer should record eval rollouts (with frames) for this logger."""
        return self.rollout_every > 0

    def log_scalars(self, scalars: dict[str, float], step: int) -> None:
        """Each `group/name` scalar becomes the time series entity `group/name` on timeline `step`.

        NaN / inf are logged as they are (a diverged loss shows as a gap or a spike, never as silence)."""
        if self._earlier is not None:  # resumed without truncate(): nothing is known to be redone
            self.truncate(lambda step, key: True)
        self.rec.set_time("step", sequence=int(step))
        for k, v in scalars.items():
            if v is not None:
                self.rec.log(k, rr.Scalars(float(v)))

    def truncate(self, keep: Callable[[int, str], bool]) -> int:
        """Log the earlier run's scalars again where `keep(step, key)`; -> how many were dropped."""
        earlier, self._earlier = self._earlier or [], None
        kept = [r for r in earlier if keep(r[0], r[1])]
        for step, key, value in kept:
            self.rec.set_time("step", sequence=step)
            self.rec.log(key, rr.Scalars(value))
        return len(earlier) - len(kept)

    def log_rollout(self, rollout: Any, step: int, tag: str = "eval") -> None:
        """A `Rollout` or a TorchRL TensorDict `[B, T]` (a collector batch), when its turn comes (`rollout_every`).

        Logged on timeline `rollout_step` with `step` held at the training step: under
        `world/rollouts/<tag>/` in the scene frame once a `Rollout` has told the logger the scene's
        frame (a TensorDict alone: under `rollouts/<tag>/nav`, nav frame); plots under `rollouts/<tag>/plots`.
        """
        n = self._rollout_calls.get(tag, 0)
        self._rollout_calls[tag] = n + 1
        if self.rollout_every <= 0 or n % self.rollout_every:
            return
        if not isinstance(rollout, Rollout):
            # a collector batch has no frame information: borrow the last Rollout's (same scene, same camera)
            meta = dataclasses.replace(self._meta, metrics=[]) if self._meta is not None else None
            rollout = rollout_from_tensordict(rollout, meta=meta)
        else:
            self._meta = rollout.meta
        in_scene = self._meta is not None  # poses can be placed in the scene frame
        if in_scene and self._scene is not None:
            log_scene(self.rec, self._scene, max_points=20_000, max_cameras=16, camera_images=False)
            self._scene = None  # once
        agents = list(range(min(self.max_agents, rollout.num_agents)))
        safe_tag = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in str(tag))
        prefix = f"world/rollouts/{safe_tag}" if in_scene else f"rollouts/{safe_tag}/nav"  # nav frame: own space
        log_rollout(self.rec, rollout, prefix=prefix, plots_prefix=f"rollouts/{safe_tag}/plots",
                    agents=agents, timeline="rollout_step", fixed_times={"step": int(step)})
        self.rollouts_logged += 1

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()  # writes the footer: the file is complete


def scalar_rows(path: str | Path) -> list[tuple[int, str, float]]:
    """Every `Scalars` value of a recording as `(step, entity, value)`, in step order."""
    rows = []
    for c in rr.chunk.RrdReader(str(path)).stream():
        rb = c.to_record_batch()
        if "Scalars:scalars" in rb.schema.names and "step" in rb.schema.names:
            key = c.entity_path.lstrip("/")
            rows += [(int(s), key, float(v[0])) for s, v in zip(rb.column("step").to_pylist(),
                                                                rb.column("Scalars:scalars").to_pylist()) if v]
    return sorted(rows, key=lambda r: r[0])


def scalar_entities(path: str | Path) -> dict[str, np.ndarray]:
    """Read back `{entity: values}` of every `Scalars` entity in a recording (tests, quick checks)."""
    out: dict[str, list] = {}
    for c in rr.chunk.RrdReader(str(path)).stream():
        rb = c.to_record_batch()
        if "Scalars:scalars" in rb.schema.names:
            vals = [v[0] for v in rb.column("Scalars:scalars").to_pylist() if v]
            out.setdefault(c.entity_path.lstrip("/"), []).extend(vals)
    return {k: np.asarray(v) for k, v in out.items()}
