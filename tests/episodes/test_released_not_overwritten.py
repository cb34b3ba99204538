"""The expert never overwrites an episodes file this project did not write."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import pytest

from wanderland_nav.episodes.generate import GeneratorSettings, generated_sibling, write_scene_episodes

RELEASED = Path(__file__).parent / "data" / "wanderland_episodes.json"  # a released-style file (no generator block)
FAST = GeneratorSettings(goal_images=False)


@pytest.fixture(scope="module")
def demo(prepared_demo_scene):
    from planners import NavMesh
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    return scene, NavMesh.load(scene.navmesh_path)


def test_generated_sibling_names():
    assert generated_sibling(Path("/s/episodes.json")) == Path("/s/episodes.generated.json")
    assert generated_sibling(Path("/s/val.json.gz")) == Path("/s/val.generated.json.gz")


@pytest.mark.parametrize("released_bytes", ["released", "foreign"])
def test_released_episodes_are_left_untouched_unless_forced(demo, tmp_path, caplog, released_bytes):
    scene, nm = demo
    out = tmp_path / "episodes.json"
    if released_bytes == "released":
        shutil.copy(RELEASED, out)
    else:  # not even our schema: a newer release format, a hand-made file
        out.write_text(json.dumps({"episodes": [{"id": 1}]}))
    before = out.read_bytes()
    with caplog.at_level(logging.INFO, logger="wanderland_nav.episodes.generate"):
        eps, summary = write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=FAST)
    side = tmp_path / "episodes.generated.json"
    assert out.read_bytes() == before, "the released file must not change"
    assert summary.out == str(side) and json.loads(side.read_text())["generator"]["name"] == "wanderland_nav.make_episodes"
    text = caplog.text
    assert f"{out} was not written by wanderland_nav.make_episodes" in text and f"episodes written to {side}" in text
    assert f"wrote {side}" in summary.format()
    # a rerun finds its own sibling up to date (and still leaves the released file alone)
    _, again = write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=FAST)
    assert again.skipped and again.out == str(side) and out.read_bytes() == before
    # force=true is the only way to replace it
    _, forced = write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=FAST, force=True)
    assert forced.out == str(out) and json.loads(out.read_text())["generator"]["seed"] == 0


def test_make_episodes_entry_point_force_reaches_the_library(prepared_demo_scene, tmp_path):
    from hydra import compose, initialize_config_dir

    from wanderland_nav.make_episodes import run

    CONF_DIR = Path(__file__).resolve().parents[2] / "conf"

    out = tmp_path / "episodes.json"
    shutil.copy(RELEASED, out)
    with initialize_config_dir(version_base="1.3", config_dir=str(CONF_DIR)):
        cfg = compose("make_episodes", overrides=[f"scenes=[{prepared_demo_scene}]", f"out={out}", "num_episodes=2",
                                           "generator.goal_images=false", "topdown=false", "progress=false",
                                           "navigation.prepare=false"])
    (s,) = run(cfg)
    assert s.out == str(tmp_path / "episodes.generated.json") and out.read_bytes() == RELEASED.read_bytes()
    cfg.force = True
    (s,) = run(cfg)
    assert s.out == str(out) and "generator" in json.loads(out.read_text())


def test_a_hand_edited_file_that_keeps_our_generator_block_is_the_users(demo, tmp_path, caplog, monkeypatch):
    """200 curated episodes must survive a navmesh change: the block's name alone does not make a file ours."""
    from wanderland_nav.episodes import generate
    from wanderland_nav.episodes.generate import not_ours_because, written_by_us

    scene, nm = demo
    out = tmp_path / "episodes.json"
    write_scene_episodes(scene, nm, out, num_episodes=3, seed=0, settings=FAST)
    assert written_by_us(out)
    data = json.loads(out.read_text())
    data["episodes"] = data["episodes"][:2]  # curated by hand; the generator block is kept
    out.write_text(json.dumps(data, indent=1))
    curated = out.read_bytes()
    assert not written_by_us(out) and "edited after it was written" in not_ours_because(out)
    monkeypatch.setattr(generate, "navmesh_fingerprint", lambda path: "another navmesh")
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.episodes.generate"):
        assert not generate.refresh_if_stale(scene, out, lambda: nm)
    assert out.read_bytes() == curated
    assert f"{out} was generated on another navmesh or splat, but its bytes are not those written" in caplog.text
    # make_episodes writes beside it, saying why
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.episodes.generate"):
        _, summary = write_scene_episodes(scene, nm, out, num_episodes=3, seed=0, settings=FAST)
    assert summary.out == str(tmp_path / "episodes.generated.json") and out.read_bytes() == curated
    assert "edited after it was written, so it is the user's" in caplog.text
    assert written_by_us(tmp_path / "episodes.generated.json")


def test_a_byte_change_alone_makes_the_file_the_users(demo, tmp_path):
    """Same content, other bytes (reformatted, an earlier version's name) or no recorded digest: not ours."""
    from wanderland_nav.episodes.generate import WRITTEN_DIGEST, not_ours_because, written_by_us

    scene, nm = demo
    out = tmp_path / "episodes.json.gz"
    write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=FAST)
    assert written_by_us(out)
    _, again = write_scene_episodes(scene, nm, out, num_episodes=2, seed=0, settings=FAST)
    assert again.skipped and again.out == str(out)  # up to date in place, not a sibling file
    plain = tmp_path / "episodes.json"
    write_scene_episodes(scene, nm, plain, num_episodes=2, seed=0, settings=FAST)
    data = json.loads(plain.read_text())
    plain.write_text(json.dumps(data))  # the same content, reformatted
    assert not written_by_us(plain)
    del data["generator"][WRITTEN_DIGEST]  # a file of an earlier version: no digest recorded
    data["generator"]["name"] = "wanderland_nav.expert"
    plain.write_text(json.dumps(data))
    assert "records no digest" in not_ours_because(plain)
    data["generator"]["name"] = "someone_else"
    plain.write_text(json.dumps(data))
    assert "no generator block" in not_ours_because(plain)
