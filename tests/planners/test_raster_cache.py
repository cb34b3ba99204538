"""The raster's batched build (same sources as per-goal exact queries), its lazy per-goal building, and its
memory/disk cache keyed by the navmesh's content (hits, misses, stale and corrupt entries)."""

from __future__ import annotations

import numpy as np
import pytest
from navmesh_meshes import bake, quad, room_with_pillars

from planners import NavMesh
from planners.raster_cache import RASTER_VERSION, clear_memory


@pytest.fixture(autouse=True)
def _cold_memory():
    clear_memory()
    yield
    clear_memory()


def _distance_of(field, samples, source, g):
    """|p s| + d(s, g) per sample for sources `[P]` of goal g (inf where -1)."""
    n = field._np
    M = n["M"]
    comb = np.where(source == M, M + g, np.maximum(source, 0))
    via = np.where(source == M, 0.0, n["c2g"][g, np.minimum(np.maximum(source, 0), max(M - 1, 0))])
    d = np.hypot(samples[:, 0] - n["src_x"][comb], samples[:, 1] - n["src_y"][comb]) + via
    return np.where(source >= 0, d, np.inf)


def test_batched_build_equals_per_goal_exact_queries(room_nm):
    field = room_nm.distance_field(room_nm.random_navigable_points(5, seed=3))
    raster = field.raster()
    raster.ensure()
    samples = raster._sample_xyz
    for g in range(len(field)):
        rows = np.flatnonzero(raster._sample_island == field.goal_island[g].item())
        ref = np.full(samples.shape[0], -1, dtype=np.int64)
        ref[rows] = field.query_local(samples[rows], np.full(rows.shape[0], g))[1]  # the first build's rule
        got = raster.source[g].astype(np.int64)
        np.testing.assert_array_equal(got >= 0, ref >= 0)
        # sources agree except on exact ties between two corners, where the distances are equal
        assert (got == ref).mean() > 0.999
        np.testing.assert_allclose(_distance_of(field, samples, got, g), _distance_of(field, samples, ref, g),
                                   rtol=0, atol=1e-9)


def test_goals_are_built_on_first_lookup_only(l_nm):
    field = l_nm.distance_field(l_nm.random_navigable_points(4, seed=1))
    raster = field.raster()
    assert not raster.built.any()
    raster.lookup(l_nm.random_navigable_points(3, seed=2), np.array([2, 2, 0]))
    assert raster.built.tolist() == [True, False, True, False]
    assert raster.cache.stats == {"memory_hits": 0, "disk_hits": 0, "built": 2}


def test_second_raster_of_a_process_reuses_the_first(l_nm, tmp_path):
    goals = l_nm.random_navigable_points(3, seed=4)
    first = l_nm.distance_field(goals).raster()
    first.ensure()
    again = l_nm.distance_field(goals[::-1].copy()).raster()  # same goals, other order
    again.ensure()
    assert again.cache.stats == {"memory_hits": 3, "disk_hits": 0, "built": 0}
    np.testing.assert_array_equal(again.source, first.source[::-1])


def test_disk_cache_hit_then_stale_navmesh_and_corrupt_file(tmp_path):
    nm = bake(room_with_pillars())
    goals = nm.random_navigable_points(2, seed=5)
    built = nm.distance_field(goals).raster(cache_dir=tmp_path)
    built.ensure()
    folder = tmp_path / f"navmesh_raster_v{RASTER_VERSION}_{nm.content_hash}"
    assert sorted(p.name for p in folder.iterdir())[-1] == "pairs.npz" and len(list(folder.glob("goal_*.npy"))) == 2

    clear_memory()  # a new process: from disk
    loaded = nm.distance_field(goals).raster(cache_dir=tmp_path)
    loaded.ensure()
    assert loaded.cache.stats == {"memory_hits": 0, "disk_hits": 2, "built": 0}
    np.testing.assert_array_equal(loaded.source, built.source)

    # another navmesh (one pillar less) never reads these rasters: its content hash differs
    other = bake(quad(0, 0, 12, 12, 0.0))
    assert other.content_hash != nm.content_hash
    fresh = other.distance_field(other.random_navigable_points(2, seed=5)).raster(cache_dir=tmp_path)
    fresh.ensure()
    assert fresh.cache.stats["built"] == 2 and fresh.cache.stats["disk_hits"] == 0

    clear_memory()  # a truncated goal file is rebuilt (and rewritten), not read
    victim = sorted(folder.glob("goal_*.npy"))[0]
    victim.write_bytes(victim.read_bytes()[:40])
    again = nm.distance_field(goals).raster(cache_dir=tmp_path)
    again.ensure()
    assert again.cache.stats == {"memory_hits": 0, "disk_hits": 1, "built": 1}
    np.testing.assert_array_equal(again.source, built.source)
    assert np.load(victim).shape == (built.source.shape[1],)


def test_content_hash_ignores_bake_time_and_survives_save_load(tmp_path):
    a, b = bake(room_with_pillars()), bake(room_with_pillars())
    assert a.bake_seconds != b.bake_seconds and a.content_hash == b.content_hash
    a.save(tmp_path / "navmesh.npz")
    assert NavMesh.load(tmp_path / "navmesh.npz").content_hash == a.content_hash
    assert bake(room_with_pillars(), agent_radius=0.3).content_hash != a.content_hash


def test_memory_cache_holds_views_of_the_raster_not_a_second_copy(l_nm, tmp_path):
    """Built rows, and rows read from disk, are kept in memory as views of the raster's own matrix."""
    from planners.raster_cache import _MEMORY

    goals = l_nm.random_navigable_points(3, seed=6)
    built = l_nm.distance_field(goals).raster(cache_dir=tmp_path)
    built.ensure()
    rows = _MEMORY[built.cache.key]["rows"]
    assert len(rows) == 3 and all(np.shares_memory(r, built.source) for r in rows.values())
    clear_memory()  # from disk: the loaded arrays are dropped for views of the new raster
    loaded = l_nm.distance_field(goals).raster(cache_dir=tmp_path)
    loaded.ensure()
    assert loaded.cache.stats["disk_hits"] == 3
    assert all(np.shares_memory(r, loaded.source) for r in _MEMORY[loaded.cache.key]["rows"].values())
    np.testing.assert_array_equal(loaded.source, built.source)


@pytest.mark.parametrize("damage", ["truncated", "empty", "bit_flipped"])
def test_a_damaged_pairs_file_is_a_miss_rebuilt_and_named(tmp_path, caplog, damage, damage_file):
    import logging

    nm = bake(room_with_pillars())
    goals = nm.random_navigable_points(2, seed=5)
    built = nm.distance_field(goals).raster(cache_dir=tmp_path)
    built.ensure()
    pairs = tmp_path / f"navmesh_raster_v{RASTER_VERSION}_{nm.content_hash}" / "pairs.npz"
    good = damage_file(pairs, damage)
    clear_memory()  # a new process, with goals not on disk: their rows are built from the pairs
    others = nm.random_navigable_points(2, seed=6)
    with caplog.at_level(logging.WARNING, logger="planners.raster_cache"):
        again = nm.distance_field(others).raster(cache_dir=tmp_path)
        again.ensure()
    clear_memory()
    reference = nm.distance_field(others).raster()
    reference.ensure()
    np.testing.assert_array_equal(again.source, reference.source)
    assert f"{pairs}: unreadable raster cache" in caplog.text and "rebuilding it" in caplog.text
    assert pairs.read_bytes() == good  # replaced by the rebuilt one


def test_a_navmesh_dropped_by_another_trim_is_held_again_on_its_next_get(monkeypatch):
    """Many scenes in one process (a scene set's BC env): a second navmesh's rows push the first one's entry out
    of the memory budget while the first env still looks up goals; its next `get` returns its rows (it raised
    KeyError) and the entry is the most recent again."""
    from types import SimpleNamespace

    import planners.raster_cache as rc

    clear_memory()
    monkeypatch.setattr(rc, "MEMORY_BUDGET", 1000)
    a, b = rc.RasterCache(SimpleNamespace(content_hash="a" * 16), 100), rc.RasterCache(SimpleNamespace(content_hash="b" * 16), 100)
    a.put(["g0"], [np.arange(100, dtype=np.int32)])  # 400 bytes
    b.put(["g1", "g2"], [np.zeros(100, np.int32), np.ones(100, np.int32)])  # 1200 bytes in all: a is dropped
    assert list(rc._MEMORY) == [b.key]
    got = a.get(["g0"])
    assert list(got) == ["g0"] and np.array_equal(got["g0"], np.arange(100))
    assert next(reversed(rc._MEMORY)) == a.key
    clear_memory()
