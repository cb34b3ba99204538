"""Batch preparation over a scene set: resumable done-manifest, failures collected, process pool and Ray."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from wanderland_nav.preparation.scene_set import SceneJob, jobs_for, prepare_one, run_batch
from wanderland_nav.scene.sets import demo_scene_set


def fake_work(job: SceneJob) -> dict:
    """Fails for scene ids containing 'bad'; otherwise counts its calls in a file beside the scene."""
    if "bad" in job.scene_id:
        raise RuntimeError(f"broken scene {job.scene_id}")
    calls = Path(job.path) / "calls"
    calls.parent.mkdir(parents=True, exist_ok=True)
    calls.write_text(str(int(calls.read_text()) + 1 if calls.is_file() else 1))
    return {"pid": os.getpid(), "episodes": job.num_episodes}


def jobs(tmp_path, ids, n=5):
    return [SceneJob(i, str(tmp_path / i), num_episodes=n) for i in ids]


@pytest.mark.parametrize("backend", ["serial", pytest.param("process", marks=pytest.mark.slow)])
def test_failures_are_collected_and_a_rerun_resumes(tmp_path, backend):
    manifest = tmp_path / "done.json"
    r = run_batch(jobs(tmp_path, ["s1", "bad1", "s2"]), manifest, workers=2, backend=backend, fn=fake_work)
    assert set(r.done) == {"s1", "s2"} and set(r.failed) == {"bad1"} and r.skipped == []
    assert "RuntimeError: broken scene bad1" in r.failed["bad1"] and "FAILED bad1: RuntimeError" in r.format()
    m = json.loads(manifest.read_text())
    assert set(m["done"]) == {"s1", "s2"} and set(m["failed"]) == {"bad1"}
    # rerun: done scenes skipped (not called again), the failed one retried
    r2 = run_batch(jobs(tmp_path, ["s1", "bad1", "s2"]), manifest, backend=backend, fn=fake_work)
    assert sorted(r2.skipped) == ["s1", "s2"] and set(r2.failed) == {"bad1"}
    assert (tmp_path / "s1" / "calls").read_text() == "1"
    # changed settings: redone
    r3 = run_batch(jobs(tmp_path, ["s1"], n=7), manifest, backend=backend, fn=fake_work)
    assert r3.skipped == [] and r3.done["s1"]["episodes"] == 7 and (tmp_path / "s1" / "calls").read_text() == "2"


def test_a_prepare_only_job_is_covered_by_an_earlier_full_job_with_the_same_preparation(tmp_path):
    from dataclasses import replace

    from wanderland_nav.scene.collision import CollisionSettings

    manifest = tmp_path / "done.json"
    run_batch(jobs(tmp_path, ["s1"]), manifest, backend="serial", fn=fake_work)
    prepare_only = [replace(j, generator=None) for j in jobs(tmp_path, ["s1"])]
    assert run_batch(prepare_only, manifest, backend="serial", fn=fake_work).skipped == ["s1"]
    coarser = [replace(j, collision=CollisionSettings(voxel_size=0.5)) for j in prepare_only]
    assert run_batch(coarser, manifest, backend="serial", fn=fake_work).skipped == []  # other preparation: redone
    assert (tmp_path / "s1" / "calls").read_text() == "2"


def test_a_scene_whose_inputs_changed_is_redone_whatever_their_times(tmp_path):
    manifest = tmp_path / "done.json"
    (tmp_path / "s1" / "lidar").mkdir(parents=True)
    scan = tmp_path / "s1" / "lidar" / "000000.bin"
    scan.write_bytes(b"\x00" * 16)
    run_batch(jobs(tmp_path, ["s1"]), manifest, backend="serial", fn=fake_work)
    assert run_batch(jobs(tmp_path, ["s1"]), manifest, backend="serial", fn=fake_work).skipped == ["s1"]
    old = scan.stat()
    scan.write_bytes(b"\x01" * 16)  # replaced as `cp -p` / `rsync -a` do: new bytes, the old time
    os.utime(scan, ns=(old.st_atime_ns, old.st_mtime_ns))
    assert run_batch(jobs(tmp_path, ["s1"]), manifest, backend="serial", fn=fake_work).skipped == []
    assert (tmp_path / "s1" / "calls").read_text() == "2"


def test_process_backend_runs_in_worker_processes_and_collects_their_failures(tmp_path):
    r = run_batch(jobs(tmp_path, ["a", "bad1", "b"]), tmp_path / "d.json", workers=2, backend="process", fn=fake_work)
    assert os.getpid() not in {d["pid"] for d in r.done.values()}
    assert set(r.done) == {"a", "b"} and "RuntimeError: broken scene bad1" in r.failed["bad1"]


def test_bad_manifest_is_named(tmp_path):
    m = tmp_path / "done.json"
    m.write_text('{"format": 99, "done": {}}')
    with pytest.raises(ValueError, match="done.json: field 'format' must be 1"):
        run_batch(jobs(tmp_path, ["a"]), m, backend="serial", fn=fake_work)
    with pytest.raises(ValueError, match="backend must be"):
        run_batch(jobs(tmp_path, ["a"]), tmp_path / "x.json", backend="dask", fn=fake_work)


def test_demo_set_jobs_carry_their_seeds(tmp_path):
    js = jobs_for(demo_scene_set(tmp_path, seeds=[3, 5]), num_episodes=4)
    assert [(j.scene_id, j.demo_seed, j.demo_preset) for j in js] == [("demo_seed_3", 3, "tiny"),
                                                                      ("demo_seed_5", 5, "tiny")]


@pytest.mark.slow  # a local Ray start (~15 s idle), like every other Ray start in the tests
def test_ray_backend_collects_failures(tmp_path):
    ray = pytest.importorskip("ray")
    here = str(Path(__file__).parent)  # Ray workers must import fake_work from this test module
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": os.pathsep.join([here, os.environ.get("PYTHONPATH", "")])}})
    try:
        r = run_batch(jobs(tmp_path, ["s1", "bad1"]), tmp_path / "d.json", workers=2, backend="ray", fn=fake_work)
    finally:
        ray.shutdown()
    assert set(r.done) == {"s1"} and set(r.failed) == {"bad1"} and r.backend == "ray"


@pytest.mark.slow
def test_prepare_one_demo_seed_end_to_end(tmp_path):
    job = jobs_for(demo_scene_set(tmp_path, seeds=[1]), num_episodes=4)[0]
    out = prepare_one(job)
    assert out["episodes"] == 4 and (tmp_path / "seed_1" / "navmesh.npz").is_file()
    assert (tmp_path / "seed_1" / "episodes.json").is_file()
