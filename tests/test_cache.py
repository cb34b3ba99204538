"""Hash-and-skip helpers shared by scene preparation, the demo scene and episode generation."""

from __future__ import annotations

import json

from wanderland_nav.cache import json_digest, read_record


def test_json_digest_is_canonical_and_sensitive():
    a = json_digest({"seed": 0, "settings": {"r": 0.6, "h": 1.5}})
    assert a == json_digest({"settings": {"h": 1.5, "r": 0.6}, "seed": 0})  # key order does not matter
    assert a != json_digest({"seed": 0, "settings": {"r": 0.3, "h": 1.5}})
    assert len(a) == 16 and int(a, 16) >= 0
    assert json_digest({"p": __import__("pathlib").Path("/x")}) == json_digest({"p": "/x"})  # str() fallback


def test_read_record_treats_bad_records_as_missing(tmp_path):
    p = tmp_path / "side.json"
    assert read_record(p) is None
    p.write_text("{not json")
    assert read_record(p) is None
    p.write_text("[1, 2]")
    assert read_record(p) is None  # a record is an object
    p.write_text(json.dumps({"settings_hash": "abc"}))
    assert read_record(p) == {"settings_hash": "abc"}


def test_one_cache_root_and_one_variable(tmp_path, monkeypatch, caplog):
    """`$WANDERLAND_NAV_CACHE` for every cache (read-only scenes' products, splat hierarchies); the hierarchy's
    old `$WANDERLAND_CACHE` is read with a deprecation warning, and ignored (said) beside the other."""
    import logging

    from wanderland_nav.cache import cache_root
    from wanderland_nav.render import lod
    from wanderland_nav.scene import products

    monkeypatch.delenv("WANDERLAND_CACHE", raising=False)
    monkeypatch.setenv("WANDERLAND_NAV_CACHE", str(tmp_path / "nav"))
    assert products.cache_root is cache_root and cache_root() == tmp_path / "nav"
    monkeypatch.setattr(lod.os, "access", lambda p, mode: False)  # a read-only splat folder
    assert lod.cache_path(tmp_path / "s" / "3dgs.ply", "ab" * 32).parent == tmp_path / "nav" / "lod"
    monkeypatch.delenv("WANDERLAND_NAV_CACHE")
    monkeypatch.setenv("WANDERLAND_CACHE", str(tmp_path / "old"))
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.cache"):
        assert cache_root() == tmp_path / "old"
    assert "$WANDERLAND_CACHE is deprecated: set $WANDERLAND_NAV_CACHE instead" in caplog.text
    monkeypatch.setenv("WANDERLAND_NAV_CACHE", str(tmp_path / "nav"))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.cache"):
        assert cache_root() == tmp_path / "nav"
    assert f"$WANDERLAND_CACHE={tmp_path / 'old'} is ignored" in caplog.text
