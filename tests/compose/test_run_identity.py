"""Run identity: every checkpoint and result row knows the config and scene it came from,
the default run folder carries it, and a run folder of another identity is refused with what differs."""

from __future__ import annotations

import json

import pytest

from wanderland_nav.compose import RunIdentityError, compose_config, run_identity, scene_identity, typed_config
from wanderland_nav.compose.identity import check_resume
from wanderland_nav.compose.schema import FitRunConfig, TrainConfig
from wanderland_nav.compose.training import default_run_dir

pytestmark = pytest.mark.usefixtures("one_thread")


def _train_dict(overrides=()):
    from omegaconf import OmegaConf

    return OmegaConf.to_container(compose_config("train", ["+exp=citywalker_rl", *overrides]), resolve=True)


def test_identity_ignores_cosmetic_keys_and_follows_settings_and_scene(tmp_path):
    (tmp_path / "navmesh.npz").write_bytes(b"navmesh v1")
    scene = scene_identity(tmp_path)
    base = run_identity(_train_dict(), scene)
    assert run_identity(_train_dict(["progress=false", "logger=rerun"]), scene)["hash"] == base["hash"]
    more = run_identity(_train_dict(["algo.ppo.total_frames=57600"]), scene)
    assert more["hash"] != base["hash"]
    (tmp_path / "navmesh.npz").write_bytes(b"navmesh v2")  # same folder, another prepared artefact
    assert run_identity(_train_dict(), scene_identity(tmp_path))["hash"] != base["hash"]
    with pytest.raises(RunIdentityError, match=r"algo.ppo.total_frames: 44800 -> 57600[\s\S]*start fresh"):
        check_resume(base, more, tmp_path, "start fresh with another run_dir=")
    with pytest.raises(RunIdentityError, match="without a recorded identity"):
        check_resume(None, more, tmp_path, "start fresh")


def test_sweep_values_get_their_own_default_run_folders(tmp_path):
    scene = scene_identity(tmp_path)
    dirs = set()
    for lr in ("1e-5", "5e-5"):
        d = _train_dict([f"algo.ppo.lr={lr}"])
        c = typed_config(compose_config("train", ["+exp=citywalker_rl", f"algo.ppo.lr={lr}"]), TrainConfig)
        dirs.add(default_run_dir(c, run_identity(d, scene)))
    assert len(dirs) == 2 and all(p.name.endswith("_seed0") and p.parent.name == "citywalker_rl" for p in dirs)


def test_train_refuses_a_run_folder_of_another_identity(demo_episodes, tmp_path):
    """Raising total_frames in the same run_dir must not silently re-print the earlier BC+RL row."""
    from wanderland_nav.rl.checkpoint import load_checkpoint
    from wanderland_nav.train import run

    scene = demo_episodes.parent
    common = ["+exp=citywalker_rl", "debug=smoke", f"scene={scene}", f"run_dir={tmp_path / 'run'}",
              "render.lod_px=4", "eval.episodes=1", "algo.bc.updates_per_round=1"]
    run(compose_config("train", common))
    ck = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    rows = json.loads((tmp_path / "run" / "results.json").read_text())
    assert {r["identity"] for r in rows.values()} == {ck["config"]["identity"]["hash"]}
    with pytest.raises(RunIdentityError, match=r"algo.ppo.total_frames: 16 -> 24[\s\S]*run_dir="):
        run(compose_config("train", [*common, "algo.ppo.total_frames=24"]))


def test_fit_refuses_a_folder_of_another_identity(tmp_path):
    from wanderland_nav.compose.fitting import fit_run_dir

    c = typed_config({"out_dir": str(tmp_path / "fit")}, FitRunConfig)
    a = run_identity({"fit": {"iterations": 10}}, {"path": "s"})
    b = run_identity({"fit": {"iterations": 20}}, {"path": "s"})
    out = fit_run_dir(c, "s", a)
    (out / "checkpoints").mkdir()
    (out / "checkpoints" / "latest.pt").write_bytes(b"x")
    assert fit_run_dir(c, "s", a) == out  # same identity: resumes
    with pytest.raises(RunIdentityError, match=r"config.fit.iterations: 10 -> 20[\s\S]*resume=false"):
        fit_run_dir(c, "s", b)


def test_fit_default_folder_carries_scene_and_identity(tmp_path, monkeypatch):
    from wanderland_nav.compose.fitting import fit_run_dir

    monkeypatch.chdir(tmp_path)
    ident = run_identity({"fit": {"iterations": 10}}, {"path": "s"})
    out = fit_run_dir(typed_config({}, FitRunConfig), "s", ident)
    assert out.parts == ("outputs", "fit", "s", ident["hash"][:8])
    assert json.loads((tmp_path / out / "identity.json").read_text())["hash"] == ident["hash"]


def test_rebaking_the_same_mesh_keeps_the_scene_identity(tmp_path):
    """navmesh.npz holds its bake time (and the zip its write time): neither may change the identity."""
    import trimesh

    from planners import NavMesh, NavMeshSettings

    floor = trimesh.creation.box(bounds=[[0, 0, -0.1], [6, 4, 0.0]])
    first = NavMesh.bake(floor, NavMeshSettings())
    first.save(tmp_path / "navmesh.npz")
    before = scene_identity(tmp_path)
    again = NavMesh.bake(floor, NavMeshSettings())
    again.bake_seconds = first.bake_seconds + 1.0  # another bake's timing, as measured
    again.save(tmp_path / "navmesh.npz")
    assert scene_identity(tmp_path) == before
    NavMesh.bake(floor, NavMeshSettings(agent_radius=0.4)).save(tmp_path / "navmesh.npz")
    assert scene_identity(tmp_path)["artefacts"]["navmesh.npz"] != before["artefacts"]["navmesh.npz"]
