"""The compiled path's fused composite (`compiled.fused_forward`) against the eager composite.

These tests run the fused kernel *uncompiled* (`fused_chunk` is plain torch, unrolled over its 16
entries), so they check the layout, gathers, sentinel padding, tile compaction and the eager tail in
seconds; compiling it (~20-60 CPU-s) is left to the slow tests in `test_render_backends.py`, which
hold the compiled images to >= 50 dB PSNR on the real splats and its gradients to the eager ones.
"""

from __future__ import annotations

import pytest
import torch
from render_dense_reference import random_scene

import wanderland_nav.render.compiled as compiled_mod
from wanderland_nav.render import rasterization
from wanderland_nav.render.packed import _project_pairs
from wanderland_nav.render.projection import quat_scale_to_covar

W, H = 29, 22


@pytest.fixture
def uncompiled(monkeypatch):
    """Every stage of `compiled=True` as its eager function: same code path, no torch.compile."""
    monkeypatch.setattr(compiled_mod, "fused_chunk_compiled", compiled_mod.fused_chunk)
    monkeypatch.setattr(compiled_mod, "project_pairs_compiled", _project_pairs)
    monkeypatch.setattr(compiled_mod, "covariances_compiled", quat_scale_to_covar)
    return monkeypatch


@pytest.mark.parametrize("min_tiles", [1, 8, 10_000], ids=["fused-to-the-end", "fused-then-eager-tail", "all-eager"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fused_composite_matches_eager(uncompiled, min_tiles, dtype):
    """Opaque splats so that pixels terminate inside fused chunks; a single active tile (min_tiles=1)
    goes through the sentinel-column padding."""
    uncompiled.setattr(compiled_mod, "MIN_FUSED_TILES", min_tiles)
    args = random_scene(400, 3, W, H, dtype, seed=5, opaque=True)
    fused_c, fused_a, _ = rasterization(*args, W, H, compiled=True, render_mode="RGB+ED")
    eager_c, eager_a, _ = rasterization(*args, W, H, render_mode="RGB+ED")
    tol = 2e-5 if dtype == torch.float32 else 1e-10
    assert float(eager_a.max()) > 0.99  # some pixels saturate: termination is exercised
    torch.testing.assert_close(fused_c, eager_c, atol=tol * float(eager_c.abs().max()), rtol=0)
    torch.testing.assert_close(fused_a, eager_a, atol=tol, rtol=0)


def test_fused_composite_counts_every_chunk_and_tail(uncompiled):
    """The fused kernel runs 16 entries at a time while >= MIN_FUSED_TILES tiles are active, then the
    group's tail runs eagerly; both parts are taken on this scene."""
    calls = {"fused": 0, "tail": 0}
    fused, tail = compiled_mod.fused_chunk, compiled_mod.composite_group

    def count_fused(q_rows, *a):
        calls["fused"] += 1
        assert q_rows.shape[1] == compiled_mod.FUSED_LEN and q_rows.shape[2] >= 2
        return fused(q_rows, *a)

    def count_tail(cur, *a):
        calls["tail"] += cur.more()
        return tail(cur, *a)

    uncompiled.setattr(compiled_mod, "fused_chunk_compiled", count_fused)
    uncompiled.setattr(compiled_mod, "composite_group", count_tail)
    uncompiled.setattr(compiled_mod, "MIN_FUSED_TILES", 8)
    args = random_scene(400, 2, W, H, torch.float32, seed=6)
    rasterization(*args, W, H, compiled=True)
    assert calls["fused"] > 0 and calls["tail"] > 0
