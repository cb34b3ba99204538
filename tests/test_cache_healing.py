"""Every cache and done-record reader takes an unreadable file (truncated, emptied) as a miss, says which file,
and the caller rebuilds and replaces it: a damaged cache never becomes a crash on every later run."""

from __future__ import annotations

import json
import logging

import pytest


@pytest.fixture(params=["truncated", "empty", "not_utf8"])
def damaged(request, tmp_path):
    path = tmp_path / "record.json"
    good = json.dumps({"format": 1, "done": {"a": {"hash": "x"}}, "failed": {}}).encode()
    path.write_bytes({"truncated": good[:10], "empty": b"", "not_utf8": b"\xff\xfe{"}[request.param])
    return path


def test_a_record_sidecar(damaged, caplog):
    from wanderland_nav.cache import read_record

    with caplog.at_level(logging.WARNING, logger="wanderland_nav.cache"):
        assert read_record(damaged) is None
    assert f"{damaged}: unreadable record" in caplog.text


def test_a_scene_sets_done_manifest(damaged, caplog):
    from wanderland_nav.preparation.scene_set import MANIFEST_FORMAT, _read_manifest

    with caplog.at_level(logging.WARNING, logger="wanderland_nav.preparation.scene_set"):
        assert _read_manifest(damaged) == {"format": MANIFEST_FORMAT, "done": {}, "failed": {}}
    assert f"{damaged}: unreadable done-manifest" in caplog.text


def test_the_resumable_stores_ledger(damaged, caplog):
    from wanderland_nav.cache import Ledger

    with caplog.at_level(logging.WARNING, logger="wanderland_nav.cache"):
        assert Ledger(damaged).entries == {}
    assert f"{damaged}: unreadable ledger" in caplog.text


def test_a_training_runs_stored_evaluations(damaged, caplog):
    from wanderland_nav.rl.recipe import _load_results

    with caplog.at_level(logging.WARNING, logger="wanderland_nav.train"):
        assert _load_results(damaged, {"phase": "bc_done"}, "h") == {}
    assert f"{damaged}: unreadable stored evaluations" in caplog.text
