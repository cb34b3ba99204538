"""The exact tile test of the packed binning (`rasterize._touches_tile`) against brute force."""

from __future__ import annotations

import torch
from render_dense_reference import random_scene

from wanderland_nav.render import rasterization
from wanderland_nav.render.binning import _tile_test_rows, _touches_tile, isect_packed
from wanderland_nav.render.rasterize import ALPHA_MIN

TS = 4


def _random_entries(n: int, seed: int = 0):
    """n elongated, rotated Gaussians (float64) and one random tile of each one's neighbourhood."""
    g = torch.Generator().manual_seed(seed)
    means2d = torch.rand(n, 2, generator=g, dtype=torch.float64) * 40
    ang = torch.rand(n, generator=g, dtype=torch.float64) * 3.1416
    sx, sy = 0.3 + 4 * torch.rand(n, generator=g, dtype=torch.float64), 0.2 + torch.rand(n, generator=g, dtype=torch.float64)
    cs, sn = torch.cos(ang), torch.sin(ang)
    cxx, cyy, cxy = cs ** 2 * sx ** 2 + sn ** 2 * sy ** 2, sn ** 2 * sx ** 2 + cs ** 2 * sy ** 2, cs * sn * (sx ** 2 - sy ** 2)
    det = cxx * cyy - cxy ** 2
    conics = torch.stack([cyy / det, -cxy / det, cxx / det], 1)
    opac = 0.01 + 0.99 * torch.rand(n, generator=g, dtype=torch.float64)
    x0 = torch.div(means2d[:, 0], TS, rounding_mode="floor") - 3
    y0 = torch.div(means2d[:, 1], TS, rounding_mode="floor") - 3
    dx, dy = torch.randint(0, 7, (n,), generator=g), torch.randint(0, 7, (n,), generator=g)
    return means2d, conics, opac, x0, y0, dx, dy


def _sigma_on_grid(means2d, conics, x0, y0, dx, dy, steps: int):
    """min of sigma over a steps x steps grid of the tile's pixel-centre rectangle (steps = TS: the centres)."""
    t = torch.linspace(0.5, TS - 0.5, steps, dtype=torch.float64)
    px = ((x0 + dx) * TS)[:, None, None] + t[None, None, :]
    py = ((y0 + dy) * TS)[:, None, None] + t[None, :, None]
    ux, uy = px - means2d[:, 0, None, None], py - means2d[:, 1, None, None]
    a, b, c = (v[:, None, None] for v in conics.unbind(1))
    return (0.5 * (a * ux * ux + c * uy * uy) + b * ux * uy).flatten(1).min(1).values


def test_tile_test_is_the_exact_minimum_over_the_tile_rectangle():
    means2d, conics, opac, x0, y0, dx, dy = _random_entries(1500)
    rows = _tile_test_rows(means2d, x0, y0, conics, opac, TS)
    kept = _touches_tile(rows, dx, dy, TS)
    limit = torch.log(opac / ALPHA_MIN)
    at_centres = _sigma_on_grid(means2d, conics, x0, y0, dx, dy, TS)
    assert kept[at_centres <= limit].all()  # never drops an entry that some pixel centre keeps
    fine = _sigma_on_grid(means2d, conics, x0, y0, dx, dy, 61)  # the continuous rectangle, finely sampled
    clear = (fine - limit).abs() > 0.5  # away from the boundary, where the sampling step (0.05 px) could decide
    assert torch.equal(kept[clear], (fine <= limit)[clear])
    assert 0.05 < kept.double().mean() < 0.95 and clear.double().mean() > 0.8  # both outcomes, mostly decidable


def test_tile_test_drops_entries_without_changing_the_image():
    """The packed path bins fewer entries than the box test but renders the same image."""
    args = random_scene(300, 3, 40, 32, torch.float64, seed=3)
    full, _, meta = rasterization(*args, 40, 32, tile_size=TS, render_mode="RGB+ED")
    ref, _, _ = rasterization(*args, 40, 32, tile_size=TS, render_mode="RGB+ED", packed=False)
    torch.testing.assert_close(full, ref, atol=1e-10, rtol=0)
    box = isect_packed(meta["camera_ids"], meta["means2d"], meta["radii"], meta["depths"], 3, TS, 10, 8)[0]
    exact = isect_packed(meta["camera_ids"], meta["means2d"], meta["radii"], meta["depths"], 3, TS, 10, 8,
                         meta["conics"], meta["opacities"])[0]
    assert exact.numel() < box.numel()


def test_blocked_projection_and_binning_match_one_block(monkeypatch):
    """Many small L2 blocks (pairs of the EWA stage, entries of the tile expansion) give the same
    image, meta and gradients as one block: blocking is a schedule, not an approximation."""
    import wanderland_nav.render.binning as binning
    import wanderland_nav.render.packed as packed

    args = list(random_scene(300, 3, 40, 32, torch.float64, seed=5))
    args[:6] = [a.detach().requires_grad_() for a in args[:6]]  # Gaussians and viewmats

    def run():
        colors, alphas, meta = rasterization(*args, 40, 32, tile_size=TS, render_mode="RGB+ED")
        grads = torch.autograd.grad(colors.square().sum() + alphas.sum(), args[:6])
        return colors, meta, grads

    one = run()
    monkeypatch.setattr(packed, "PAIR_BLOCK", 37)
    monkeypatch.setattr(binning, "CACHE_BLOCK", 53)
    many = run()
    assert one[1]["camera_ids"].numel() > 10 * 37  # many blocks really ran
    torch.testing.assert_close(many[0], one[0], atol=1e-12, rtol=0)
    assert torch.equal(many[1]["camera_ids"], one[1]["camera_ids"])
    assert torch.equal(many[1]["gaussian_ids"], one[1]["gaussian_ids"])
    for a, b in zip(many[2], one[2]):
        torch.testing.assert_close(a, b, atol=1e-12, rtol=0)


def test_padded_stable_sort_equals_torch_stable_sort_with_ties_and_the_pad_value():
    from wanderland_nav.render.binning import PAD_TO_RADIX, RADIX_MIN, stable_sort

    g = torch.Generator().manual_seed(3)
    for dtype, n in ((torch.int16, PAD_TO_RADIX), (torch.int32, RADIX_MIN - 1), (torch.int64, 20000)):
        keys = torch.randint(0, 50, (n,), generator=g).to(dtype)  # many ties: stability matters
        keys[::97] = torch.iinfo(dtype).max  # real keys equal to the pad value stay before the pads
        got, want = stable_sort(keys), torch.sort(keys, stable=True)
        assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1])
        assert got[1].max() < n  # no pad position leaks into the permutation
