"""Prepare + expert episodes over a scene set in parallel, resumably (the library under `prepare scene=<set>`,
`make_episodes scene=<set>`, and the preparation `train` / `evaluate` run before a set).

Each scene is one task: build it if it is a demo seed, `prepare_scene` (collision mesh, navmesh) and
`write_scene_episodes` (expert episodes, when the job has generator settings). Tasks run as Ray tasks when `ray` is importable and a cluster
is reachable or startable (`backend="ray"`), else in a local `ProcessPoolExecutor` (`"process"`), or in
this process (`"serial"`, for debugging). Why not a home-made scheduler: Ray already places tasks over
machines; the local pool covers one machine without it.

Resumable: `done_manifest` (JSON, written atomically after every finished scene) records each finished
scene with the hash of the job settings; a rerun skips those and retries failures. A scene that raises
does not stop the others: its error is recorded under `failed` and reported at the end.
"""

from __future__ import annotations

import hashlib
import json
import logging
import multiprocessing as mp
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import torch

from planners import NavMesh, NavMeshSettings
from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
from wanderland_nav.scene.generated import make_generated_scene
from wanderland_nav.scene.collision import CollisionSettings
from wanderland_nav.scene.sets import SceneSet
from wanderland_nav.preparation.scene import input_digests, prepare_scene, scene_inputs

log = logging.getLogger(__name__)
MANIFEST_FORMAT = 1


@dataclass(frozen=True)
class SceneJob:
    """One scene's work; picklable, so it crosses into worker processes and Ray tasks."""

    scene_id: str
    path: str
    num_episodes: int = 100
    seed: int = 0
    demo_seed: int | None = None  # a procedural demo scene to build first
    demo_preset: str = "tiny"  # its preset (a district: its size)
    generator: GeneratorSettings | None = GeneratorSettings()  # expert episodes with these; None: prepare only
    collision: CollisionSettings = CollisionSettings()  # the composed `navigation` group's settings
    navmesh: NavMeshSettings | None = None  # null: NavMeshSettings() (up axis: the scene's)
    force: bool = False  # redo (and rewrite) even when the done-manifest or the artefacts' hashes say done
    demo_generator: str = "demo"  # the procedural generator of `demo_seed`: demo | district

    @property
    def expert(self) -> bool:
        return self.generator is not None

    def settings_hash(self) -> str:
        """Every setting of the job: a scene done with the same hash is skipped."""
        return _digest({k: v for k, v in self._hashed().items() if k not in ("scene_id", "path", "force")})

    def prepare_hash(self) -> str:
        """The settings of the preparation alone: a prepare-only job (`expert=False`, the scene already
        has episodes) is also covered by an earlier full job with the same preparation."""
        keep = ("demo_seed", "demo_preset", "collision", "navmesh")
        return _digest({k: v for k, v in self._hashed().items() if k in keep})

    def _hashed(self) -> dict:
        """The fields the hashes cover; the generator only when it is not the demo (so a demo set's done-manifest
        written before districts existed still covers it)."""
        d = asdict(self)
        if d["demo_generator"] == "demo":
            d.pop("demo_generator")
        return d

    def inputs_hash(self) -> str:
        """The contents of the scene folder's inputs (scans, poses, meta); "demo" for a demo seed, whose
        folder the job itself builds from its settings. A scan replaced after the run is seen here."""
        if self.demo_seed is not None:
            return "demo"
        root = Path(self.path)
        return _digest(input_digests(root, scene_inputs(root)))

    def done_by(self, entry: dict | None) -> bool:
        """Whether a done-manifest entry covers this job (same settings, same input contents)."""
        if entry is None or self.force or entry.get("inputs_hash") != self.inputs_hash():
            return False
        return entry.get("settings_hash") == self.settings_hash() or (
            not self.expert and entry.get("prepare_hash") == self.prepare_hash())


def _digest(d: dict) -> str:
    return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


def prepare_one(job: SceneJob) -> dict:
    """Build (demo), prepare and write expert episodes for one scene; returns figures for the manifest."""
    torch.set_num_threads(1)  # one task per core: no oversubscription
    t0 = time.perf_counter()
    if job.demo_seed is not None:
        make_generated_scene(Path(job.path), job.demo_generator, job.demo_seed, job.demo_preset)
    scene = prepare_scene(job.path, collision=job.collision, navmesh=job.navmesh, force=job.force)
    out = {"prepare_s": time.perf_counter() - t0}
    if job.expert:
        episodes, summary = write_scene_episodes(scene, NavMesh.load(scene.navmesh_path),
                                                 scene.products / "episodes.json", num_episodes=job.num_episodes,
                                                 seed=job.seed, settings=job.generator, force=job.force)
        out.update(episodes=len(episodes), expert_skipped=bool(summary.skipped))
    out["seconds"] = time.perf_counter() - t0
    return out


@dataclass
class BatchReport:
    done: dict[str, dict] = field(default_factory=dict)  # scene id -> figures (this run and earlier ones)
    failed: dict[str, str] = field(default_factory=dict)  # scene id -> error (this run)
    skipped: list[str] = field(default_factory=list)  # already done by an earlier run
    backend: str = ""
    seconds: float = 0.0

    def format(self) -> str:
        lines = [f"  {sid}: " + ("done by an earlier run" if sid in self.skipped else f"{d.get('seconds', 0):.1f}s")
                 + (f", {d['episodes']} episodes" if "episodes" in d else "") for sid, d in self.done.items()]
        lines.append(f"{len(self.done)} scenes done ({len(self.skipped)} from an earlier run), {len(self.failed)} "
                     f"failed, {self.seconds:.1f}s on {self.backend}")
        lines += [f"  FAILED {sid}: {err.strip().splitlines()[-1] if err.strip() else err}"
                  for sid, err in self.failed.items()]
        return "\n".join(lines)


def jobs_for(scene_set: SceneSet, *, num_episodes: int = 100, seed: int = 0,
             generator: GeneratorSettings | None = GeneratorSettings(),
             collision: CollisionSettings = CollisionSettings(), navmesh: NavMeshSettings | None = None,
             force: bool = False) -> list[SceneJob]:
    """One job per scene of the set (demo seeds are built first); `generator=None`: prepare only."""
    seeds = scene_set.demo.get("seeds") or [None] * len(scene_set)
    return [SceneJob(e.scene_id, str(e.path), num_episodes, seed, s, scene_set.demo.get("preset", "tiny"), generator,
                     collision, navmesh, force, scene_set.demo.get("generator", "demo"))
            for e, s in zip(scene_set.entries, seeds)]


def _read_manifest(path: Path) -> dict:
    if not path.is_file():
        return {"format": MANIFEST_FORMAT, "done": {}, "failed": {}}
    try:
        m = json.loads(path.read_text())
    except (OSError, ValueError) as e:  # truncated or emptied: every scene is checked again (each skips when up to date)
        log.warning("%s: unreadable done-manifest (%s); every scene is checked again and the manifest replaced",
                    path, e)
        return {"format": MANIFEST_FORMAT, "done": {}, "failed": {}}
    if not isinstance(m, dict) or m.get("format") != MANIFEST_FORMAT or not isinstance(m.get("done"), dict):
        raise ValueError(f"{path}: field 'format' must be {MANIFEST_FORMAT} with a 'done' object; "
                         "delete it to start over")
    return m


def _pick_backend(backend: str) -> str:
    if backend != "auto":
        return backend
    try:
        import ray  # noqa: F401
    except ImportError:
        return "process"
    return "ray"


def run_batch(jobs: list[SceneJob], done_manifest: str | Path, *, workers: int = 2, backend: str = "auto",
              fn: Callable[[SceneJob], dict] | None = None) -> BatchReport:
    """Run `fn` (default `prepare_one`) over the jobs not yet done (by `settings_hash`), `workers` at a time;
    never raises for a scene."""
    t0, path = time.perf_counter(), Path(done_manifest)
    manifest = _read_manifest(path)
    report = BatchReport(backend=_pick_backend(backend))
    todo = []
    for j in jobs:
        prev = manifest["done"].get(j.scene_id)
        if j.done_by(prev):
            report.done[j.scene_id] = prev
            report.skipped.append(j.scene_id)
        else:
            todo.append(j)

    def finished(job: SceneJob, result: dict | None, error: str | None) -> None:
        if error is None:
            entry = {**result, "settings_hash": job.settings_hash(), "prepare_hash": job.prepare_hash(),
                     "inputs_hash": job.inputs_hash()}
            manifest["done"][job.scene_id] = report.done[job.scene_id] = entry
            manifest["failed"].pop(job.scene_id, None)
        else:
            manifest["failed"][job.scene_id] = report.failed[job.scene_id] = error
            log.error("scene %s failed: %s", job.scene_id, error.strip().splitlines()[-1] if error.strip() else error)
        atomic_write_json(path, manifest)

    runner = {"ray": _run_ray, "process": _run_pool, "serial": _run_serial}.get(report.backend)
    if runner is None:
        raise ValueError(f"backend must be auto | ray | process | serial, got {backend!r}")
    if todo:
        runner(todo, fn or prepare_one, max(1, int(workers)), finished)
    report.seconds = time.perf_counter() - t0
    return report


def _guarded(fn, job):
    """Run one job; a failure comes back as text (a traceback), so one scene never stops the rest."""
    try:
        return fn(job), None
    except Exception:  # noqa: BLE001 - every per-scene error is reported, none stops the batch
        return None, traceback.format_exc()


def _run_serial(todo, fn, workers, finished) -> None:
    for job in todo:
        finished(job, *_guarded(fn, job))


def _run_pool(todo, fn, workers, finished) -> None:
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as ex:
        pending = {ex.submit(_guarded, fn, job): job for job in todo}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                job = pending.pop(fut)
                try:
                    finished(job, *fut.result())
                except Exception:  # noqa: BLE001 - a dead worker process fails its scene only
                    finished(job, None, traceback.format_exc())


def _run_ray(todo, fn, workers, finished) -> None:
    import ray

    if not ray.is_initialized():
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)  # joins RAY_ADDRESS if set
    task = ray.remote(num_cpus=1, max_retries=0)(_guarded)
    pending = {task.remote(fn, job): job for job in todo}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        job = pending.pop(ready[0])
        try:
            finished(job, *ray.get(ready[0]))
        except Exception:  # noqa: BLE001 - a lost worker fails its scene only
            finished(job, None, traceback.format_exc())


def prepare_scene_set(scene_set: SceneSet, done_manifest: str | Path, *, num_episodes: int, seed: int,
                      goal_images: bool, workers: int = 2, backend: str = "process",
                      collision: CollisionSettings = CollisionSettings(),
                      navmesh: NavMeshSettings | None = None) -> dict[str, str]:
    """Prepare every scene of the set with these settings and make episodes where there are none
    (resumably: the done-manifest skips scenes done with the same settings). Like the single-scene entry
    points, a scene's existing `episodes.json` is used as it is, while its collision mesh and navmesh
    are brought up to date with `collision` / `navmesh`. Returns `{scene_id: folder}` of the ready ones."""
    jobs = [replace(j, generator=None) if (Path(j.path) / "episodes.json").is_file() else j
            for j in jobs_for(scene_set, num_episodes=num_episodes, seed=seed,
                              generator=GeneratorSettings(goal_images=goal_images), collision=collision,
                              navmesh=navmesh)]
    failed = {}
    if jobs:
        report = run_batch(jobs, done_manifest, workers=workers, backend=backend)
        log.info("scene set: %s", report.format())
        failed = report.failed
    if failed:
        log.warning("scene set: %d scene(s) left out after failing: %s", len(failed), sorted(failed))
    ready = {e.scene_id: str(e.path) for e in scene_set
             if e.scene_id not in failed and (e.path / "episodes.json").is_file()}
    if not ready:
        raise RuntimeError(f"{scene_set.source}: no scene of the set could be prepared: {failed}")
    return ready
