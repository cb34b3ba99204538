"""Goal views are keyed by the episode set and the splat they were rendered from, and written as one set:
a killed run of another seed, a second episodes file or a changed `3dgs.ply` can never leave an episodes
file "up to date" over views that are not its own."""

from __future__ import annotations

import copy
import hashlib

import pytest

from wanderland_nav.episodes import load_episode_file
from wanderland_nav.episodes import generate as G
from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
from wanderland_nav.episodes.sampler import SamplerSettings

TINY = GeneratorSettings(sampler=SamplerSettings(batch_size=64), goal_image_width=16, goal_image_height=12)


@pytest.fixture(scope="module")
def demo(prepared_demo_scene):
    from planners import NavMesh
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    return scene, NavMesh.load(scene.navmesh_path)


def _views(out):
    f = load_episode_file(out)
    return {e.extras["goal_image"]: hashlib.sha256((out.parent / e.extras["goal_image"]).read_bytes()).hexdigest()
            for e in f.episodes}


def test_a_killed_run_of_another_seed_leaves_the_first_set_intact(demo, tmp_path, monkeypatch):
    scene, nm = demo
    out = tmp_path / "episodes.json"
    write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=TINY)
    before = _views(out)
    real = G.render_goal_images

    def killed(gaussians_path, goals, yaws, R, paths, **kw):  # the first view lands, then the run dies
        real(gaussians_path, goals[:1], yaws[:1], R, paths[:1], **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(G, "render_goal_images", killed)
    with pytest.raises(KeyboardInterrupt):
        write_scene_episodes(scene, nm, out, num_episodes=2, seed=1, settings=TINY, force=True)
    monkeypatch.setattr(G, "render_goal_images", real)
    _, summary = write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=TINY)
    assert summary.skipped and _views(out) == before  # seed 0's own views, byte for byte
    assert not [p for p in (tmp_path / "goal_images").iterdir() if p.name.startswith(".")]  # no temporary left


def test_two_episode_files_beside_one_scene_keep_their_own_views(demo, tmp_path):
    scene, nm = demo
    a, b = tmp_path / "episodes.json", tmp_path / "episodes_n2_s1.json"
    write_scene_episodes(scene, nm, a, num_episodes=2, seed=0, settings=TINY)
    first = _views(a)
    write_scene_episodes(scene, nm, b, num_episodes=2, seed=1, settings=TINY)
    assert _views(a) == first and set(_views(b)).isdisjoint(first)
    _, summary = write_scene_episodes(scene, nm, a, num_episodes=2, seed=0, settings=TINY)
    assert summary.skipped


def test_a_changed_splat_renders_new_views_and_drops_the_old_set(demo, tmp_path):
    from wanderland_nav.render import Gaussians

    scene, nm = demo
    scene = copy.copy(scene)
    g = Gaussians.load(scene.gaussians_path)
    scene.gaussians_path = tmp_path / "3dgs.ply"
    g.save(scene.gaussians_path)
    out = tmp_path / "ep" / "episodes.json"
    write_scene_episodes(scene, nm, out, num_episodes=1, seed=0, settings=TINY)
    old = _views(out)
    g.sh_dc = g.sh_dc - 1.0  # the same geometry, darker colours: every view changes
    g.save(scene.gaussians_path)
    _, summary = write_scene_episodes(scene, nm, out, num_episodes=1, seed=0, settings=TINY)
    new = _views(out)
    assert not summary.skipped and set(new).isdisjoint(old) and list(new.values()) != list(old.values())
    assert not (out.parent / next(iter(old))).exists()  # the earlier set is gone, not left beside the new one


def test_a_view_replaced_by_hand_is_not_up_to_date(demo, tmp_path):
    scene, nm = demo
    out = tmp_path / "episodes.json"
    write_scene_episodes(scene, nm, out, num_episodes=1, seed=0, settings=TINY)
    view = tmp_path / next(iter(_views(out)))
    view.write_bytes(view.read_bytes()[:-8] + bytes(8))
    _, summary = write_scene_episodes(scene, nm, out, num_episodes=1, seed=0, settings=TINY)
    assert not summary.skipped


def test_no_episode_at_all_is_refused_with_the_navmesh_figures_and_nothing_written(demo, tmp_path):
    import dataclasses

    from planners import NavMesh
    from wanderland_nav.episodes.generate import EmptyEpisodeSetError
    from wanderland_nav.preparation.scene import load_collision_mesh

    scene, nm = demo
    # an agent as wide as the walkways: what is left of the navmesh is crumbs no route fits on
    mesh = load_collision_mesh(scene.collision_mesh_path)
    out = tmp_path / "episodes.json"
    st = GeneratorSettings(sampler=SamplerSettings(batch_size=64, max_rounds=3), goal_images=False)
    for radius, why in ((5.5, r"the drawn points fall off the navmesh \(off_mesh: \d+ of \d+ candidates\); the "
                               r"navmesh has 1 island\(s\), [\d.]+ m\^2 walkable"),
                        (8.0, r"no walkable area to draw from; the navmesh has 0 island\(s\), 0\.0 m\^2 walkable")):
        wide = NavMesh.bake(mesh, dataclasses.replace(nm.settings, agent_radius=radius))
        with pytest.raises(EmptyEpisodeSetError, match=rf"episodes\.json: 0 of 5 episodes for scene .* nothing "
                                                       rf"written: {why}.*agent_radius {radius:g} m.*"
                                                       r"navigation\.navmesh\.agent_radius"):
            write_scene_episodes(scene, wide, out, num_episodes=5, seed=0, settings=st)
        assert not out.exists()
