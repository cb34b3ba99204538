"""LPIPS structure checks with synthetic weights (real weights are user-provided, never downloaded)."""

from __future__ import annotations

import pytest
import torch

from wanderland_nav.gsfit.lpips import CHANNELS, LPIPS


def _weights(seed=0):
    g = torch.Generator().manual_seed(seed)
    shapes = {0: (64, 3, 11, 11), 3: (192, 64, 5, 5), 6: (384, 192, 3, 3), 8: (256, 384, 3, 3), 10: (256, 256, 3, 3)}
    bb = {}
    for i, s in shapes.items():
        bb[f"features.{i}.weight"] = torch.randn(s, generator=g) * 0.05
        bb[f"features.{i}.bias"] = torch.zeros(s[0])
    lin = {f"lin{i}.model.1.weight": torch.rand(1, c, 1, 1, generator=g) for i, c in enumerate(CHANNELS)}
    return bb, lin


def test_lpips_properties_and_file_loading(tmp_path):
    bb, lin = _weights()
    m = LPIPS(bb, lin)
    g = torch.Generator().manual_seed(1)
    a = torch.rand(2, 64, 64, 3, generator=g)
    b = (a + 0.2 * torch.randn(2, 64, 64, 3, generator=g)).clamp(0, 1)
    c = (a + 0.05 * torch.randn(2, 64, 64, 3, generator=g)).clamp(0, 1)
    dab, dac = m(a, b), m(a, c)
    assert dab.shape == (2,) and torch.allclose(m(a, a), torch.zeros(2), atol=1e-6)
    assert torch.allclose(dab, m(b, a), atol=1e-6) and (dab > dac).all()  # symmetric, monotone in noise
    torch.save(bb, tmp_path / "alexnet.pth")
    torch.save(lin, tmp_path / "alex.pth")
    m2 = LPIPS.from_files(tmp_path / "alexnet.pth", tmp_path / "alex.pth")
    assert torch.allclose(m2(a, b), dab)
    with pytest.raises(FileNotFoundError, match="missing.pth"):
        LPIPS.from_files(tmp_path / "missing.pth", tmp_path / "alex.pth")
    del lin["lin2.model.1.weight"]
    with pytest.raises(ValueError, match="lin2"):
        LPIPS(bb, lin)
