"""Learning-curve PNG from metrics.csv and evaluations with intervals."""

from __future__ import annotations

from wanderland_nav.viz.curves import read_metrics, write_learning_curves
from wanderland_nav.evaluation.stats import Estimate


def test_curves_png_from_logged_metrics(tmp_path):
    (tmp_path / "metrics.csv").write_text("step,key,value\n400,train/SR,0.25\n400,train/reward_mean,-0.1\n"
                                          "800,train/SR,0.5\n800,losses/critic,1.0\n")
    assert read_metrics(tmp_path / "metrics.csv")["train/SR"] == [(400, 0.25), (800, 0.5)]
    est = {c: Estimate(0.5, 0.3, 0.7, 20) for c in ("SR", "SPL")}
    png = write_learning_curves(tmp_path, {"BC": (0, est), "BC+RL": (800, est)})
    assert png == tmp_path / "curves.png" and png.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curves.png", "metrics.csv"]  # no temp file left
    empty = tmp_path / "empty"
    empty.mkdir()
    assert write_learning_curves(empty, {}) is None and not any(empty.iterdir())
