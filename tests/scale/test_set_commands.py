"""`prepare` / `make_episodes` over `scene=<set>` with the per-scene work replaced by a recorder: the composed
`navigation.*` and `generator.*` settings reach every scene's job and key the done-manifest, failures are
collected, and the single-scene commands refuse a set."""

from __future__ import annotations

import json

import pytest

from wanderland_nav.preparation import scene_set as prepare_set
from wanderland_nav.compose import compose_config


@pytest.fixture
def recorded(monkeypatch):
    """Replace `prepare_one` (build, prepare, expert) with a recorder; scene id 'demo_seed_9' fails."""
    jobs = []

    def fake(job):
        if job.scene_id == "demo_seed_9":
            raise RuntimeError("navmesh bake failed")
        jobs.append(job)
        return {"seconds": 0.0, **({"episodes": job.num_episodes} if job.expert else {})}

    monkeypatch.setattr(prepare_set, "prepare_one", fake)
    return jobs


def _set(tmp_path, seeds="[0,1]"):
    return ["scene=demo_set", f"scene.set.root={tmp_path}", f"scene.set.seeds={seeds}", "scene.set.backend=serial"]


def test_prepare_over_a_set_uses_the_navigation_overrides_and_resumes(tmp_path, recorded):
    from wanderland_nav.prepare import run

    report = run(compose_config("prepare", [*_set(tmp_path), "navigation.navmesh.agent_radius=0.4",
                                            "navigation.collision.voxel_size=0.15"]))
    assert sorted(report.done) == ["demo_seed_0", "demo_seed_1"] and not report.failed
    assert [(j.navmesh.agent_radius, j.collision.voxel_size, j.expert) for j in recorded] == [(0.4, 0.15, False)] * 2
    assert [j.demo_seed for j in recorded] == [0, 1]
    again = run(compose_config("prepare", [*_set(tmp_path), "navigation.navmesh.agent_radius=0.4",
                                           "navigation.collision.voxel_size=0.15"]))
    assert sorted(again.skipped) == ["demo_seed_0", "demo_seed_1"] and len(recorded) == 2  # done: not run again
    run(compose_config("prepare", [*_set(tmp_path), "navigation.navmesh.agent_radius=0.3"]))
    assert len(recorded) == 4  # other navigation settings: prepared again
    forced = run(compose_config("prepare", [*_set(tmp_path), "navigation.navmesh.agent_radius=0.3", "force=true"]))
    assert forced.skipped == [] and recorded[-1].force and len(recorded) == 6


def test_make_episodes_over_a_set_carries_the_generator_settings(tmp_path, recorded):
    from wanderland_nav.make_episodes import run

    report = run(compose_config("make_episodes", [*_set(tmp_path), "num_episodes=7", "seed=3",
                                                  "generator.goal_images=false", "generator.step_size=0.5",
                                                  "navigation.navmesh.agent_radius=0.45"]))
    assert {sid: d["episodes"] for sid, d in report.done.items()} == {"demo_seed_0": 7, "demo_seed_1": 7}
    j = recorded[0]
    assert (j.num_episodes, j.seed, j.generator.goal_images, j.generator.step_size, j.navmesh.agent_radius) == \
        (7, 3, False, 0.5, 0.45)
    # a prepare-only run after it is covered by the same preparation; another episode count is not
    from wanderland_nav.prepare import run as prepare

    assert sorted(prepare(compose_config("prepare", [*_set(tmp_path), "navigation.navmesh.agent_radius=0.45"]))
                  .skipped) == ["demo_seed_0", "demo_seed_1"]
    assert run(compose_config("make_episodes", [*_set(tmp_path), "num_episodes=8", "generator.goal_images=false",
                                                "navigation.navmesh.agent_radius=0.45"])).skipped == []


def test_a_failing_scene_is_reported_and_the_others_finish(tmp_path, recorded, capsys):
    from wanderland_nav.make_episodes import run

    report = run(compose_config("make_episodes", [*_set(tmp_path, "[0,9,1]"), "num_episodes=2"]))
    assert sorted(report.done) == ["demo_seed_0", "demo_seed_1"] and list(report.failed) == ["demo_seed_9"]
    out = capsys.readouterr().out
    assert "FAILED demo_seed_9: RuntimeError: navmesh bake failed" in out and "1 failed" in out
    assert list(json.loads((tmp_path / "prepare_done.json").read_text())["failed"]) == ["demo_seed_9"]


def test_make_episodes_refuses_out_or_a_list_with_a_set(tmp_path):
    from wanderland_nav.make_episodes import run

    with pytest.raises(ValueError, match="is a scene set: its episodes go beside each scene"):
        run(compose_config("make_episodes", [*_set(tmp_path), f"out={tmp_path / 'e.json'}"]))


@pytest.mark.parametrize("entry, run", [("export_usd", "run"), ("fit", "run_fit")])
def test_single_scene_commands_refuse_a_set(tmp_path, entry, run):
    from importlib import import_module

    with pytest.raises(ValueError, match="scene=demo_set is a scene set; this command takes one scene"):
        getattr(import_module(f"wanderland_nav.{entry}"), run)(compose_config(entry, _set(tmp_path)))
