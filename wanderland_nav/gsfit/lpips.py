"""LPIPS (Zhang et al. 2018, 'alex' variant) in plain torch, from locally provided weights.

The framework never downloads weights (ARCHITECTURE.md: no network at run time), so LPIPS is computed
only when the user points at two local files:
- `backbone_path`: a torchvision AlexNet state dict (`alexnet-owt-7be5be79.pth`; keys
  `features.{0,3,6,8,10}.{weight,bias}`; any `classifier.*` keys are ignored);
- `lin_path`: the LPIPS linear calibration for AlexNet (`lpips/weights/v0.1/alex.pth`; keys
  `lin{0..4}.model.1.weight`, shape [1, C, 1, 1]).
Without them evaluation simply reports no LPIPS column; it is never faked with random weights.

Images: [C, H, W, 3] float in [0, 1]; returns [C] distances (lower is more similar).
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F

# LPIPS input normalisation (applied after mapping [0, 1] -> [-1, 1])
_SHIFT = torch.tensor([-0.030, -0.088, -0.188])
_SCALE = torch.tensor([0.458, 0.448, 0.450])
# AlexNet conv layers: (state-dict index, stride, padding, max-pool before it)
_CONVS = ((0, 4, 2, False), (3, 1, 2, True), (6, 1, 1, True), (8, 1, 1, False), (10, 1, 1, False))
CHANNELS = (64, 192, 384, 256, 256)


class LPIPS(torch.nn.Module):
    """Frozen AlexNet feature stack + per-layer linear weights; `forward(pred, target) -> [C]`."""

    def __init__(self, backbone: dict[str, torch.Tensor], lin: dict[str, torch.Tensor]):
        super().__init__()
        self.weights = torch.nn.ParameterList()
        self.biases = torch.nn.ParameterList()
        self.lins = torch.nn.ParameterList()
        for i, (idx, _, _, _) in enumerate(_CONVS):
            for key, store in ((f"features.{idx}.weight", self.weights), (f"features.{idx}.bias", self.biases)):
                if key not in backbone:
                    raise ValueError(f"LPIPS backbone state dict lacks {key!r}")
                store.append(torch.nn.Parameter(backbone[key].float(), requires_grad=False))
            key = f"lin{i}.model.1.weight"
            if key not in lin:
                raise ValueError(f"LPIPS linear weights lack {key!r}")
            w = lin[key].float()
            if w.shape != (1, CHANNELS[i], 1, 1):
                raise ValueError(f"LPIPS {key}: expected shape (1, {CHANNELS[i]}, 1, 1), got {tuple(w.shape)}")
            self.lins.append(torch.nn.Parameter(w, requires_grad=False))
        self.register_buffer("shift", _SHIFT.view(1, 3, 1, 1))
        self.register_buffer("scale", _SCALE.view(1, 3, 1, 1))

    @classmethod
    def from_files(cls, backbone_path: str | Path, lin_path: str | Path) -> "LPIPS":
        loaded = []
        for p in (backbone_path, lin_path):
            p = Path(p)
            if not p.is_file():
                raise FileNotFoundError(f"LPIPS weights not found: {p}")
            loaded.append(torch.load(p, map_location="cpu", weights_only=True))
        return cls(*loaded).eval()

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """[B, 3, H, W] normalised input -> the five ReLU outputs."""
        feats = []
        for (_, stride, pad, pool), w, b in zip(_CONVS, self.weights, self.biases):
            if pool:
                x = F.max_pool2d(x, kernel_size=3, stride=2)
            x = F.relu(F.conv2d(x, w, b, stride=stride, padding=pad))
            feats.append(x)
        return feats

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        if pred.shape != target.shape or pred.dim() != 4 or pred.shape[-1] != 3:
            raise ValueError(f"LPIPS: expected two [C,H,W,3] images of one shape, got {tuple(pred.shape)}, "
                             f"{tuple(target.shape)}")
        c = pred.shape[0]
        x = torch.cat([pred, target]).permute(0, 3, 1, 2) * 2 - 1  # one backbone pass for both
        x = (x - self.shift) / self.scale
        d = torch.zeros(c, dtype=x.dtype, device=x.device)
        for f, lin in zip(self.features(x), self.lins):
            f = f / (f.pow(2).sum(dim=1, keepdim=True).sqrt() + 1e-10)  # unit length per location
            diff = (f[:c] - f[c:]) ** 2
            d = d + F.conv2d(diff, lin).mean(dim=(1, 2, 3))
        return d
