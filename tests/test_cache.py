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
