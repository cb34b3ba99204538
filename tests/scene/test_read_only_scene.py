"""A read-only scene folder (released data on a read-only share): detected when the scene is loaded, and
every generated file goes to the documented cache folder instead of failing after the computation."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from wanderland_nav.scene import products
from wanderland_nav.scene.collision import CollisionSettings


def _listing(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def test_a_read_only_scene_writes_its_products_to_the_cache_folder(tiny_demo_scene, tmp_path, monkeypatch):
    from wanderland_nav.compose.scene import scene_episodes
    from wanderland_nav.episodes.generate import GeneratorSettings
    from wanderland_nav.preparation.scene import prepare_scene

    ro = tmp_path / "share" / "demo_tiny"
    shutil.copytree(tiny_demo_scene, ro)
    before = _listing(ro)
    real = products.writable
    # the tests run as root, which writes through permission bits: stand in for a read-only mount
    monkeypatch.setattr(products, "writable", lambda folder: Path(folder) != ro and real(folder))
    monkeypatch.setenv(products.CACHE_ENV, str(tmp_path / "cache"))
    scene = prepare_scene(ro, collision=CollisionSettings(voxel_size=0.3))
    cache = scene.products
    assert cache.parent == tmp_path / "cache" / "scenes" and cache.name.startswith("demo_tiny-")
    assert scene.collision_mesh_path == cache / "collision_mesh.ply" and scene.navmesh_path == cache / "navmesh.npz"
    scene, episodes = scene_episodes(scene, None, num=3, seed=0, generator=GeneratorSettings(goal_images=False))
    assert episodes == cache / "episodes.json" and episodes.is_file()
    assert _listing(ro) == before  # nothing written beside the scene
    again = prepare_scene(ro, collision=CollisionSettings(voxel_size=0.3))  # found again, up to date
    assert again.meta["prepare"]["collision_mesh"]["skipped"] and again.episodes_path == episodes


def test_a_cache_folder_that_cannot_be_made_is_named_with_the_setting(tmp_path, monkeypatch):
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setattr(products, "writable", lambda folder: False)
    monkeypatch.setenv(products.CACHE_ENV, str(blocker))
    with pytest.raises(OSError, match=rf"{tmp_path / 'ro'} is read-only and its cache folder .* cannot be made.*"
                                      r"set WANDERLAND_NAV_CACHE"):
        products.products_dir(tmp_path / "ro")


def test_writable_is_tried_not_guessed(tmp_path):
    assert products.writable(tmp_path) and not products.writable(tmp_path / "missing")
    assert list(tmp_path.iterdir()) == []  # the probe is removed


def test_a_folder_without_write_bits_is_read_only_even_for_root(tmp_path, monkeypatch):
    """Shared data laid out without write bits stays as it is, even where the process could write through them
    (root): the scene's products and a splat's hierarchy go to the user cache instead."""
    from wanderland_nav.render.lod import cache_path
    ro = tmp_path / "shared"
    ro.mkdir()
    (ro / "s.ply").write_bytes(b"ply")
    ro.chmod(0o555)
    monkeypatch.setenv(products.CACHE_ENV, str(tmp_path / "cache"))
    try:
        assert not products.writable(ro)
        assert cache_path(ro / "s.ply", "ab" * 32).parent == tmp_path / "cache" / "lod"
        assert products.products_dir(ro).parent == tmp_path / "cache" / "scenes"
    finally:
        ro.chmod(0o755)
    assert cache_path(ro / "s.ply", "ab" * 32) == ro / "s.lod.npz"  # a writable folder keeps it beside the splat
