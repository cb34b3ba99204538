"""`scene.set` through the composition root: train steps every scene (BC on the first), evaluate reports a
row per scene, preparation hears the composed navigation group, and collector=ray reaches the recipe.

The set is a folder of two links to the test run's prepared demo scene (it has episodes, so nothing is
prepared again): seconds, not the minutes three fresh demo seeds take (those run in tests/scale, slow).
"""

from __future__ import annotations

import json

import pytest

from wanderland_nav.compose import compose_config, typed_config
from wanderland_nav.compose.schema import EvaluateConfig, SceneSetSettings, TrainConfig

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture
def linked_set(demo_episodes, tmp_path):
    """A manifest folder `set/{a,b}` whose scenes are the prepared demo (episodes included)."""
    root = tmp_path / "set"
    root.mkdir()
    for name in ("a", "b"):
        (root / name).symlink_to(demo_episodes.parent, target_is_directory=True)
    return root


def set_overrides(root) -> list[str]:
    return ["scene=demo_set", "scene.set.seeds=null", f"scene.set.manifest={root}", f"scene.set.root={root}"]


def test_train_recipe_over_a_set_steps_and_clones_every_scene(linked_set, tmp_path):
    from wanderland_nav.compose.training import training_recipe
    from wanderland_nav.envs.multi_scene import MultiSceneNavEnv

    cfg = compose_config("train", ["+exp=citywalker_rl", "debug=smoke", "collector=ray", f"run_dir={tmp_path / 'run'}",
                                   "render.lod_px=4", *set_overrides(linked_set)])
    c = typed_config(cfg, TrainConfig)
    recipe, work = training_recipe(c, {"seed": 0})
    assert work.per_scene and list(work.folders) == ["a", "b"]
    assert recipe.evaluator.per_scene and list(recipe.evaluator.scenes) == ["a", "b"]
    assert sorted(recipe.identity["scene"]["scenes"]) == ["a", "b"]
    assert recipe.ray == {"address": None, "cpus_per_worker": 1.0, "memory_per_worker_gb": None,
                            "sync_timeout_s": 600.0, "worker_niceness": 0}
    train_env = recipe.env_fn()
    assert isinstance(train_env, MultiSceneNavEnv) and tuple(train_env.batch_size) == (2,)
    assert train_env.num_active == 2  # batch 2 over 2 scenes: one agent each
    train_env.close()
    bc_env = recipe.bc_env_fn()
    assert isinstance(bc_env, MultiSceneNavEnv) and tuple(bc_env.batch_size) == (2,)
    assert list(bc_env.scene_episodes) == ["a", "b"]  # BC labels come from every scene's expert paths
    bc_env.close()
    recipe.logger.close()


def test_evaluate_expert_over_a_set_has_a_row_per_scene(linked_set, tmp_path):
    from wanderland_nav.evaluate import run

    res = run(compose_config("evaluate", ["debug=smoke", "reference=expert", "split=null", f"out={tmp_path / 'out'}",
                                          *set_overrides(linked_set)]))
    assert {k for k in res.summary if k.startswith("scene/")} == {"scene/a", "scene/b"}
    assert res.summary["overall"]["episodes"] == 8 and res.summary["overall"]["SR"] == 1.0
    assert (tmp_path / "out" / "eval_expert.json").is_file()
    # existing episodes are kept; the scenes were still brought up to the composed navigation settings
    done = json.loads((linked_set / "prepare_done.json").read_text())["done"]
    assert set(done) == {"a", "b"} and "episodes" not in done["a"]


def test_scene_set_preparation_uses_the_composed_navigation_group():
    from wanderland_nav.preparation.scene_set import jobs_for
    from wanderland_nav.scene.sets import demo_scene_set

    s = demo_scene_set("/tmp/unused", seeds=[0])
    default = typed_config(compose_config("train", ["scene=demo_set"]), TrainConfig).navigation
    wider = typed_config(compose_config("train", ["scene=demo_set", "navigation.navmesh.agent_radius=0.4"]),
                         TrainConfig).navigation
    jobs = [jobs_for(s, collision=n.collision, navmesh=n.navmesh)[0] for n in (default, wider)]
    assert jobs[1].navmesh.agent_radius == 0.4
    assert jobs[0].settings_hash() != jobs[1].settings_hash()  # a rerun with other settings prepares again


def test_a_set_without_seeds_or_manifest_is_refused():
    from wanderland_nav.compose.scene_sets import set_root
    from wanderland_nav.scene.sets import ManifestError, scene_set_from_config

    c = typed_config(compose_config("evaluate", ["scene=demo_set", "scene.set.seeds=null", "scene.set.root=null"]),
                     EvaluateConfig)
    with pytest.raises(ManifestError, match="scene.set: neither `seeds`"):
        scene_set_from_config(c.scene)
    with pytest.raises(ValueError, match="scene.set: give `root`"):
        set_root(SceneSetSettings())


def test_one_scene_is_a_set_of_one_and_a_set_refuses_one_scenes_file(linked_set, demo_episodes):
    """`scene_work`: the demo is one scene keyed by its name (rows not per scene); a set is its scenes, each with
    its own episodes.json, and an episodes file naming one scene is refused with the setting named."""
    from wanderland_nav.compose.scene_sets import scene_work

    one = typed_config(compose_config("evaluate", ["debug=smoke", f"episodes={demo_episodes}"]), EvaluateConfig)
    work = scene_work(one.scene, one.navigation, num_episodes=4, seed=0, goal_images=False, episodes=one.episodes)
    assert not work.per_scene and list(work.episodes.values()) == [demo_episodes] and work.label == work.name
    assert work.identity()["episodes_path"] == str(demo_episodes)

    c = typed_config(compose_config("evaluate", ["debug=smoke", *set_overrides(linked_set)]), EvaluateConfig)
    many = scene_work(c.scene, c.navigation, num_episodes=4, seed=0, goal_images=False)
    assert many.per_scene and list(many.folders) == ["a", "b"]
    assert many.episodes == {sid: linked_set / sid / "episodes.json" for sid in ("a", "b")}
    assert many.label == "scene set demo_set (2 scenes: a, b)" and set(many.identity()["scenes"]) == {"a", "b"}
    with pytest.raises(ValueError, match=r"episodes.path=x.json names one scene's file; a scene set uses each"):
        scene_work(c.scene, c.navigation, num_episodes=4, seed=0, goal_images=False, episodes="x.json",
                   episodes_key="episodes.path")
