"""Expert episodes on the prepared tiny demo scene: paths on the navmesh, lengths, cameras, determinism."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from wanderland_nav.episodes import load_episode_file, load_episodes
from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
from wanderland_nav.episodes.goal_images import goal_camera_poses
from wanderland_nav.episodes.paths import last_heading_nav, polyline_length
from wanderland_nav.episodes.sampler import SamplerSettings

FAST = dict(goal_images=False)


@pytest.fixture(scope="module")
def demo(prepared_demo_scene):
    from planners import NavMesh
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    return scene, NavMesh.load(scene.navmesh_path)


def test_expert_paths_on_navmesh_in_scene_and_near_cameras(demo, demo_episodes):
    scene, nm = demo
    f = load_episode_file(demo_episodes)
    eps = f.episodes
    assert len(eps) >= 4, f.extras["summary"]
    R = scene.nav_from_scene
    cams = scene.camera_centers() @ R.T  # [M, 3] nav frame
    lo, hi = scene.points.min(0) - 0.5, scene.points.max(0) + 0.5
    settings = f.extras["generator"]["settings"]["sampler"]
    for e in eps:
        pts = np.concatenate([e.reference_path, e.gt_locations])
        snapped = np.asarray(nm.snap_point(pts, max_distance=1e6))
        assert np.abs(snapped - pts).max() < 0.05, "expert path leaves the navmesh"
        assert ((pts >= lo) & (pts <= hi)).all(), "expert path leaves the scene bounds"
        # geodesic_distance is the length of the stored corner path and agrees with the planner
        assert e.geodesic_distance == pytest.approx(polyline_length(e.reference_path), abs=1e-3)
        g = float(np.asarray(nm.geodesic_distance(e.start_position[None], e.goal_position[None]))[0])
        assert e.geodesic_distance == pytest.approx(g, rel=0.05, abs=0.1)
        assert settings["min_geodesic"] <= e.geodesic_distance <= settings["max_geodesic"] + 0.1
        np.testing.assert_allclose(e.reference_path[0], e.start_position)
        np.testing.assert_allclose(e.reference_path[-1], e.goal_position)
        # dense locations: <= 0.25 m apart on the ground plane, same ends, gt_steps moves
        steps = np.linalg.norm(np.diff(e.gt_locations @ R.T, axis=0)[:, :2], axis=-1)
        assert steps.max() <= 0.25 + 1e-3 and e.gt_steps == len(e.gt_locations) - 1
        assert polyline_length(e.gt_locations) == pytest.approx(e.geodesic_distance, rel=0.05, abs=0.1)
        # start and goal within the configured radius of a capture camera (ground plane)
        for p in (e.start_position, e.goal_position):
            q = p @ R.T
            d = np.linalg.norm(cams[:, :2] - q[:2], axis=-1)
            assert (d <= settings["camera_radius"] + 1e-6).any()
        # start heading faces the first path segment
        d0 = (e.reference_path[1] - e.reference_path[0]) @ R.T
        assert abs(np.angle(np.exp(1j * (e.start_yaw(scene.up_axis) - np.arctan2(d0[1], d0[0]))))) < 1e-3
        assert 0 < e.goal_radius <= 3.0 and e.extras["euclidean_distance"] > e.goal_radius
        assert e.extras["up_axis"] == scene.up_axis and e.split in ("train", "val", "test")
    # episodes are spread: no two share both start and goal within min_separation
    s = np.stack([e.start_position for e in eps]); g = np.stack([e.goal_position for e in eps])
    ds = np.linalg.norm(s[:, None] - s[None], axis=-1); dg = np.linalg.norm(g[:, None] - g[None], axis=-1)
    np.fill_diagonal(ds, np.inf)
    assert (np.maximum(ds, dg) >= settings["min_separation"] - 1e-3).all()


def test_same_seed_same_bytes_and_rerun_is_noop(demo, demo_episodes, tmp_path):
    scene, nm = demo
    # the fixture's arguments again, into another folder: the very same bytes
    a = tmp_path / "a" / "episodes.json"
    _, s1 = write_scene_episodes(scene, nm, a, num_episodes=8, seed=0, settings=GeneratorSettings(**FAST))
    assert not s1.skipped and a.read_bytes() == demo_episodes.read_bytes()
    # same arguments on the same file: nothing is rewritten
    before = os.stat(a).st_mtime_ns
    eps, s2 = write_scene_episodes(scene, nm, a, num_episodes=8, seed=0, settings=GeneratorSettings(**FAST))
    assert s2.skipped and os.stat(a).st_mtime_ns == before and len(eps) == s1.kept
    # another seed regenerates, and gives other episodes
    _, s3 = write_scene_episodes(scene, nm, a, num_episodes=2, seed=1,
                                 settings=GeneratorSettings(sampler=SamplerSettings(batch_size=64), **FAST))
    d = json.loads(a.read_text())
    assert not s3.skipped and d["generator"]["seed"] == 1 and len(d["episodes"]) == 2
    assert d["episodes"][0]["start_position"] != json.loads(demo_episodes.read_text())["episodes"][0]["start_position"]


def test_camera_radius_is_respected(demo):
    scene, nm = demo
    from wanderland_nav.episodes.generate import generate_episodes

    st = GeneratorSettings(sampler=SamplerSettings(camera_radius=1.0, min_geodesic=1.0, min_ratio=1.0, batch_size=64),
                           **FAST)
    eps, summ = generate_episodes(scene, nm, num_episodes=4, seed=1, settings=st)
    assert eps, summ.format()
    R = scene.nav_from_scene
    cams = scene.camera_centers() @ R.T
    for e in eps:
        for p in (e.start_position, e.goal_position):
            q = p @ R.T
            assert np.linalg.norm(cams[:, :2] - q[:2], axis=-1).min() <= 1.0 + 1e-6
    assert sum(summ.length_hist.values()) == summ.kept == len(eps)
    assert set(summ.rejections) >= {"not_near_camera", "too_short", "too_straight", "too_close"}


def test_expert_entry_point_writes_episodes_and_topdown(prepared_demo_scene, tmp_path):
    from wanderland_nav.compose import compose_config
    from wanderland_nav.make_episodes import run

    cfg = compose_config("make_episodes", [f"scene={prepared_demo_scene}", "num_episodes=3", "seed=0",
                                    f"out={tmp_path / 'ep.json'}", "navigation.prepare=false", "progress=false",
                                    "generator.goal_images=false", "generator.sampler.batch_size=64"],
                         list_key="scenes")
    (summary,) = run(cfg)
    assert summary.kept == len(load_episodes(tmp_path / "ep.json")) >= 1
    png = tmp_path / "ep_topdown.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


def test_goal_images_face_the_last_segment(demo, tmp_path):
    """One small render (the CPU renderer costs seconds per view): the PNG exists, shows the scene, is linked."""
    from PIL import Image

    scene, nm = demo
    st = GeneratorSettings(sampler=SamplerSettings(batch_size=64), goal_image_width=32, goal_image_height=24)
    eps, _ = write_scene_episodes(scene, nm, tmp_path / "episodes.json", num_episodes=1, seed=5, settings=st)
    assert len(eps) == 1
    key = load_episode_file(tmp_path / "episodes.json").extras["generator"]["args_hash"]
    for e in eps:
        assert e.extras["goal_image"] == f"goal_images/{key}/{e.episode_id:05d}.png"  # one folder per set
        img = np.asarray(Image.open(tmp_path / e.extras["goal_image"]))
        assert img.shape == (24, 32, 3)
        assert img.std() > 5.0  # not a blank frame: the splats are in view
        # the camera looks along the last path segment, level, from above the goal
        R = scene.nav_from_scene
        c = e.reference_path @ R.T
        T = goal_camera_poses(c[-1:], np.array([last_heading_nav(c)]), R, height=1.5)[0].numpy()
        fwd = R @ T[:3, 2]  # OpenCV +z (viewing direction) in the nav frame
        seg = c[-1] - c[-2]
        np.testing.assert_allclose(fwd[:2] / np.linalg.norm(fwd[:2]), seg[:2] / np.linalg.norm(seg[:2]), atol=1e-6)
        assert abs(fwd[2]) < 1e-9
        np.testing.assert_allclose(R @ T[:3, 3], c[-1] + [0, 0, 1.5], atol=1e-6)


def test_our_file_on_another_navmesh_is_regenerated_with_its_own_settings(demo, tmp_path, monkeypatch):
    from wanderland_nav.episodes import generate

    scene, nm = demo
    settings = GeneratorSettings(sampler=SamplerSettings(batch_size=64, min_geodesic=2.0), **FAST)
    ours = tmp_path / "ours" / "episodes.json"
    write_scene_episodes(scene, nm, ours, num_episodes=3, seed=2, settings=settings)
    recorded = json.loads(ours.read_text())["generator"]
    assert not generate.refresh_if_stale(scene, ours, lambda: nm)                 # same navmesh: left as it is
    foreign = tmp_path / "theirs" / "episodes.json"
    foreign.parent.mkdir()
    foreign.write_text(json.dumps({k: v for k, v in json.loads(ours.read_text()).items() if k != "generator"}))
    before = foreign.read_bytes()
    monkeypatch.setattr(generate, "navmesh_fingerprint", lambda path: "another navmesh")
    assert generate.refresh_if_stale(scene, ours, lambda: nm)                     # rebuilt for the new navmesh ...
    again = json.loads(ours.read_text())["generator"]
    assert again["args_hash"] != recorded["args_hash"]
    assert (again["seed"], again["num_episodes"], again["settings"]) == (2, 3, recorded["settings"])  # ... as before
    assert not generate.refresh_if_stale(scene, ours, lambda: nm)                 # and now up to date
    assert not generate.refresh_if_stale(scene, foreign, lambda: nm) and foreign.read_bytes() == before  # not ours: untouched


def test_goal_images_through_the_fused_camera_equal_the_reference(demo, tmp_path):
    """Goal views render on the fused camera by default; the torch reference gives the same PNGs (8-bit levels
    may differ by one where a value sits on a rounding edge)."""
    from PIL import Image

    from wanderland_nav.episodes.goal_images import render_goal_images
    from wanderland_nav.render import fused

    if not fused.available():
        pytest.skip("the fused camera kernel cannot be built here (no C++ compiler)")
    scene, _ = demo
    R = scene.nav_from_scene
    pick = scene.cameras[:: max(1, len(scene.cameras) // 4)][:4]
    goals = np.stack([np.linalg.inv(c.cam_from_world)[:3, 3] for c in pick]) @ R.T - [0.0, 0.0, 1.5]
    yaws = np.linspace(0.0, 2 * np.pi, len(goals), endpoint=False)
    images = {}
    for backend in ("fused", "torch"):
        out = [tmp_path / backend / f"{i}.png" for i in range(len(goals))]
        out[0].parent.mkdir()
        render_goal_images(scene.gaussians_path, goals, yaws, R, out, height=1.5, width=48, image_height=32,
                           batch=3, backend=backend)
        images[backend] = np.stack([np.asarray(Image.open(p)).astype(int) for p in out])
    diff = np.abs(images["fused"] - images["torch"])
    assert images["fused"].shape == (len(goals), 32, 48, 3) and images["fused"].std() > 5.0
    assert diff.max() <= 1 and diff.mean() < 0.01, (diff.max(), diff.mean())
    assert GeneratorSettings().render_backend == "fused"
    assert "render_backend" not in GeneratorSettings().to_dict()  # how the views are rendered is not what they are
