"""The demo's products side by side per navigation settings, and `make_env`'s default camera."""

from __future__ import annotations

from pathlib import Path

from wanderland_nav.compose import compose_config
from wanderland_nav.compose.schema import MakeEnvConfig, PrepareConfig, TrainConfig, typed_config


def _where_prepared(monkeypatch, app, schema, overrides):
    """The folder `prepared_scene` prepares for `app`'s composed config (the demo build and the bake recorded, not
    run: the folder is decided before either)."""
    import wanderland_nav.compose.scene as scene

    seen = {}
    monkeypatch.setattr(scene, "make_demo_scene", lambda path, **kw: seen.setdefault("built", Path(path)))
    monkeypatch.setattr(scene, "prepare_scene", lambda path, **kw: seen.setdefault("prepared", (Path(path), kw)))
    c = typed_config(compose_config(app, overrides), schema)
    scene.prepared_scene(c.scene, c.navigation, prepare=True)
    assert seen["built"] == seen["prepared"][0]
    return seen["prepared"]


def test_smoke_and_the_main_job_prepare_the_demo_in_folders_of_their_own(monkeypatch):
    """Switching `debug=smoke` and the default never re-bakes one folder: the coarser smoke voxels are another
    navmesh and other episodes, kept beside the main job's."""
    main, main_kw = _where_prepared(monkeypatch, "train", TrainConfig, ["+exp=citywalker_rl"])
    smoke, smoke_kw = _where_prepared(monkeypatch, "train", TrainConfig, ["+exp=citywalker_rl", "debug=smoke"])
    assert main == Path("data/scenes/demo_tiny")  # the main job's folder is where it always was
    assert main_kw["collision"].voxel_size != smoke_kw["collision"].voxel_size
    assert smoke != main and smoke.parent == main.parent and smoke.name.startswith("demo_tiny_nav")
    for app, schema in (("make_env", MakeEnvConfig), ("prepare", PrepareConfig)):  # every smoke run shares it
        assert _where_prepared(monkeypatch, app, schema, ["debug=smoke"])[0] == smoke
    assert _where_prepared(monkeypatch, "make_env", MakeEnvConfig, [])[0] == main
    recast, _ = _where_prepared(monkeypatch, "train", TrainConfig, ["navigation=recast"])
    assert recast not in (main, smoke)  # any other agent: its own folder too


def test_make_env_without_a_policy_has_the_main_jobs_camera():
    env = typed_config(compose_config("make_env", []), MakeEnvConfig)
    main = typed_config(compose_config("train", ["+exp=citywalker_rl"]), TrainConfig)
    assert [env.env.camera.height, env.env.camera.width] == list(main.policy["image_size"]) == [32, 32]
    assert env.render.lod_px == main.render.lod_px == 2.0
    from wanderland_nav.compose.make_env import make_env

    assert "32 x 32 px" in make_env.__doc__ and "2-px" in make_env.__doc__


def test_a_smoke_study_builds_its_source_beside_the_main_jobs_demo(monkeypatch, tmp_path):
    """The study's train cells prepare `scene=<source folder>` with the recipe's navigation: the source folder is
    the one that navigation keys, never the main job's `demo_tiny` (which the smoke voxels would re-bake)."""
    import wanderland_nav.compose.scene as scene
    from wanderland_nav.compose.schema import study_config
    from wanderland_nav.grounding_study.cells import StudyCells
    from wanderland_nav.grounding_study.plan import plan_cells

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(scene, "make_demo_scene", lambda path, **kw: Path(path).mkdir(parents=True, exist_ok=True))
    folders = {}
    for name, overrides in (("smoke", ["+study=grounding", "debug=smoke"]), ("full", ["+study=grounding"])):
        c = study_config(compose_config("study", overrides))
        folders[name] = StudyCells(c, tmp_path / name, None, plan_cells(c.study)).source()
    assert folders["full"] == tmp_path / "data/scenes/demo_tiny"
    assert folders["smoke"].name.startswith("demo_tiny_nav")
