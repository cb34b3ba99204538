"""NavEnv on the real parts: the prepared tiny demo scene, its navmesh, its episodes, the splat renderer."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from wanderland_nav import keys
from wanderland_nav.envs import ExpertPolicy, NavEnvConfig, RandomPolicy
from wanderland_nav.evaluation.loop import run_evaluation
from wanderland_nav.envs.factory import make_nav_env


@pytest.fixture(scope="module")
def demo_parts(prepared_demo_scene, demo_episodes):
    from planners import NavMesh
    from wanderland_nav.render import Gaussians
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    g = Gaussians.load(scene.gaussians_path)
    idx = torch.randperm(len(g), generator=torch.Generator().manual_seed(0))[:3000]
    return scene, NavMesh.load(scene.navmesh_path), g[idx]  # a subsample keeps the CPU renderer fast


def _episodes(scene):
    from wanderland_nav.episodes import load_episodes

    return load_episodes(scene.episodes_path)


def blind_config(**term):
    c = NavEnvConfig()
    c.camera.enabled = False
    c.camera.width = c.camera.height = 8
    for k, v in term.items():
        setattr(c.termination, k, v)
    return c


def test_expert_reaches_quality_bar_and_random_does_not(demo_parts, demo_episodes):
    scene, navmesh, _ = demo_parts
    env = make_nav_env(scene, _episodes(scene), navmesh, config=blind_config(max_steps=300), batch_size=8)
    res = run_evaluation(env, ExpertPolicy(env), name="expert")
    o = res.summary["overall"]
    assert o["episodes"] == len(env.table) and o["SR"] >= 0.95 and o["SPL"] >= 0.9, res.table
    for r in res.records:  # the expert's travelled length never beats the geodesic by more than the goal radius
        assert r["path_length"] >= r["shortest_length"] - float(env.table.goal_radius.max()) - 0.3
    env2 = make_nav_env(scene, _episodes(scene), navmesh, config=blind_config(max_steps=60), batch_size=8)
    rnd = run_evaluation(env2, RandomPolicy(env2.action_spec, seed=0), name="random").summary["overall"]
    assert rnd["SR"] < 0.95 * o["SR"] and rnd["SPL"] < 0.9


def test_frames_and_distances_match_the_navmesh(demo_parts, demo_episodes):
    scene, navmesh, _ = demo_parts
    env = make_nav_env(scene, _episodes(scene), navmesh, config=blind_config(), batch_size=4)
    td = env.reset()
    ep = td[keys.EPISODE_INDEX].flatten()
    starts = np.stack([env.episodes[i].start_position for i in ep.tolist()])
    goals = np.stack([env.episodes[i].goal_position for i in ep.tolist()])
    # agent position (nav) maps back onto the episode start (scene) and the distance field agrees
    # with the navmesh's own geodesic query
    back = env.nav_to_scene(td[keys.AGENT_POSITION]).numpy()
    assert np.allclose(back[:, [0, 2]], starts[:, [0, 2]], atol=0.05)  # -y up: x, z are horizontal
    geo = torch.as_tensor(navmesh.geodesic_distance(back, goals)).float()
    assert torch.allclose(td[keys.DISTANCE_TO_GOAL].flatten(), geo, rtol=0.02, atol=0.1)
    yaw = np.array([env.episodes[i].start_yaw(scene.up_axis) for i in ep.tolist()])
    assert np.allclose(td[keys.AGENT_YAW].flatten().numpy(), yaw, atol=1e-5)
    # many steps of motion: always on the navmesh, never through walls
    pol = RandomPolicy(env.action_spec, seed=1)
    for _ in range(15):
        td = pol(td)
        _, td = env.step_and_maybe_reset(td)
        assert navmesh.is_navigable(env.nav_to_scene(td[keys.AGENT_POSITION]).numpy()).all()


def test_specs_and_real_rendering(demo_parts, demo_episodes):
    scene, navmesh, gaussians = demo_parts
    c = NavEnvConfig()
    c.camera.width, c.camera.height, c.camera.history, c.camera.depth = 24, 16, 2, True
    c.termination.max_steps = 50
    env = make_nav_env(scene, _episodes(scene), navmesh, config=c, batch_size=2, gaussians=gaussians)
    check_env_specs(env)
    td = env.reset()
    rgb = td[keys.RGB]
    assert rgb.shape == (2, 2, 16, 24, 3) and rgb.dtype == torch.uint8 and rgb.float().std() > 1.0  # not blank
    assert (td[keys.DEPTH] > 0).any()
    td = ExpertPolicy(env)(td)
    nxt = env.step(td)["next"]
    assert not torch.equal(nxt[keys.RGB][:, -1], rgb[:, -1])  # the view changed as the agents moved


def test_sharded_rendering_gives_the_same_images_for_any_thread_count(demo_parts, demo_episodes):
    """The env's cameras render in fixed groups of `render_chunk` on `render_threads` threads: the
    images are bit-identical with 1 and 2 threads, and match one unsharded renderer call."""
    from wanderland_nav.envs.camera import AgentCamera
    from wanderland_nav.render import render

    scene, navmesh, gaussians = demo_parts
    c = NavEnvConfig()
    c.camera.width = c.camera.height = 16
    c.camera.depth = True
    env = make_nav_env(scene, _episodes(scene), navmesh, config=c, batch_size=10, gaussians=gaussians)
    env.reset()
    images = {}
    for threads in (1, 2):
        c.camera.render_threads, c.camera.render_chunk = threads, 3
        cam = AgentCamera(c.camera, scene.nav_from_scene, render, gaussians, "cpu")
        images[threads] = cam.render(env._pos, env._yaw)
    (rgb1, d1), (rgb2, d2) = images.values()
    assert rgb1.float().std() > 1.0  # not blank
    assert torch.equal(rgb1, rgb2) and torch.equal(d1, d2)
    # groups vs one renderer call for all 10: the composite sums colours in another chunk order (rounding)
    one = render(gaussians, cam.cam_from_world(env._pos, env._yaw), cam.K.expand(10, 3, 3), 16, 16,
                 render_mode="RGB+ED", background=cam.background)
    assert (rgb1.int() - (one.rgb * 255.0 + 0.5).to(torch.uint8).int()).abs().max() <= 1
    torch.testing.assert_close(d1, torch.nan_to_num(one.depth), rtol=1e-5, atol=1e-4)
