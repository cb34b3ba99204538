"""The benchmark's tasks: what each shows, the env each builds over the same routes, and the refusals."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from policies import make_policy
from wanderland_nav import keys
from wanderland_nav.envs import NavEnvConfig
from wanderland_nav.benchmark.tasks import TASK_NAMES, check_reads, check_task_episodes, hidden_reads, make_task, task_env_config


def test_each_task_shows_the_shared_keys_and_only_its_own_goal():
    shared = {keys.RGB, keys.DEPTH, keys.PAST_POSITIONS}
    goal = {keys.GOAL_VECTOR, keys.GOAL_POSE, keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE, keys.INSTRUCTION_TOKENS}
    own = {"pointgoal": {keys.GOAL_VECTOR, keys.GOAL_POSE}, "imagegoal": {keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE},
           "instruction": {keys.INSTRUCTION_TOKENS}}
    for name in TASK_NAMES:
        t = make_task(name)
        assert set(t.observes) & goal == own[name] and shared <= set(t.observes)
        assert keys.AGENT_POSITION not in t.observes and keys.EXPERT_ACTION not in t.observes
    assert make_task("pointgoal", "route").label == "pointgoal(route)"
    assert make_task("imagegoal", "route").goal_input == "goal"  # the goal input is point-goal's setting only
    with pytest.raises(ValueError, match="task 'objectgoal': expected one of"):
        make_task("objectgoal")


def test_policies_are_refused_from_tasks_that_hide_what_they_read():
    small = dict(image_size=(32, 32), dim=32, depth=1, heads=2)
    citywalker = make_policy("cnn", image_size=(32, 32))  # reads rgb and goal_vector, as CityWalker
    nomad_image = make_policy("nomad", use_goal_vector=False, unet_hidden=16, **small)
    nomad_point = make_policy("nomad", use_goal_vector=True, unet_hidden=16, **small)
    instruction = make_policy("instruction", text_layers=1, max_tokens=32, **small)
    assert hidden_reads(make_task("pointgoal"), citywalker.in_keys) == []
    assert hidden_reads(make_task("imagegoal"), nomad_image.in_keys) == []
    assert hidden_reads(make_task("imagegoal"), nomad_point.in_keys) == [keys.GOAL_VECTOR]
    assert hidden_reads(make_task("instruction"), instruction.in_keys) == []
    with pytest.raises(ValueError, match=r"cnn reads \['goal_vector'\], which task instruction does not show"):
        check_reads(make_task("instruction"), citywalker.in_keys, "cnn")
    with pytest.raises(ValueError, match=r"reads \['instruction_tokens'\], which task pointgoal"):
        check_reads(make_task("pointgoal"), instruction.in_keys, "instruction")


def test_point_goal_env_config_is_the_env_as_it_is():
    cfg = NavEnvConfig()
    assert task_env_config(make_task("pointgoal"), cfg) is cfg
    assert task_env_config(make_task("pointgoal", "route"), cfg) is cfg
    img = task_env_config(make_task("imagegoal"), cfg)
    assert (img.goal_image, img.observe_goal_image) == ("render", True) and cfg.goal_image == "auto"
    assert task_env_config(make_task("instruction"), cfg).observe_instruction is True
    blind = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, enabled=False))
    with pytest.raises(ValueError, match="camera.enabled is false"):
        task_env_config(make_task("imagegoal"), blind)


@pytest.fixture(scope="module")
def demo_parts(prepared_demo_scene, demo_episodes):
    from planners import NavMesh
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.render import Gaussians
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    g = Gaussians.load(scene.gaussians_path)
    idx = torch.randperm(len(g), generator=torch.Generator().manual_seed(0))[:3000]
    return scene, NavMesh.load(scene.navmesh_path), g[idx], load_episodes(demo_episodes)[:4]


def _env(parts, task, episodes=None):
    from wanderland_nav.envs.factory import make_nav_env

    scene, navmesh, g, eps = parts
    cfg = NavEnvConfig()
    cfg.camera.width = cfg.camera.height = 16
    cfg.camera.history = 2
    return make_nav_env(scene, episodes or eps, navmesh, gaussians=g, config=task_env_config(task, cfg), batch_size=2)


def test_the_three_tasks_pose_the_same_routes_with_their_own_goal(demo_parts):
    point, image, text = (_env(demo_parts, make_task(n)) for n in TASK_NAMES)
    for env in (image, text):  # the same starts, goals and lengths: the tasks compare episode by episode
        assert torch.equal(env.table.start_position, point.table.start_position)
        assert torch.equal(env.shortest_length, point.shortest_length)
    td = image.reset()
    assert image.goal_view_mask.all() and td.get(keys.HAS_GOAL_IMAGE).all()
    views = image._goal_images.float()  # [E, H, W, 3]: rendered, and each episode's its own
    assert views.amax() > 0 and not torch.equal(views[0], views[1])
    check_task_episodes(make_task("imagegoal"), image, "demo")
    td = text.reset()
    tokens = td.get(keys.INSTRUCTION_TOKENS)[0]
    decoded = bytes((tokens[tokens > 0] - 1).tolist()).decode("utf-8")
    assert decoded == demo_parts[3][0].instruction_text and len(decoded.split()) >= 3
    check_task_episodes(make_task("instruction"), text, "demo")


def test_episodes_that_cannot_pose_the_task_are_refused(demo_parts):
    silent = [dataclasses.replace(e, instruction_text="") if i == 1 else e for i, e in enumerate(demo_parts[3])]
    env = _env(demo_parts, make_task("instruction"), silent)
    with pytest.raises(ValueError, match=r"task instruction: 1 of 4 episodes have no instruction text \(first: "
                                         r"episodes\[1\]"):
        check_task_episodes(make_task("instruction"), env, "demo")
