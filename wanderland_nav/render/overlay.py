"""Per-camera Gaussians rendered into the same call as the scene: moving things each camera sees alone.

Why: a batch of env cameras shares one static scene, but every env instance has its own moving objects
(pedestrians). `render(..., extra=CameraGaussians)` appends camera c's rows to camera c's Gaussians (its
level-of-detail cut, or the whole plain set), so the rasteriser sorts them together by depth: occlusion
between the scene and the objects is exact, and there is still one renderer call per camera group.

Rows are activated (metres, covariances, opacities, RGB in [0, 1]); padding rows carry opacity 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .sh import SH_C0


@dataclass
class CameraGaussians:
    """M Gaussians per camera, scene frame, activated.

    means     [C, M, 3]     centres (metres)
    covars    [C, M, 3, 3]  world covariances
    opacities [C, M]        in [0, 1] (0: an unused row)
    rgb       [C, M, 3]     colour in [0, 1], view-independent
    """

    means: torch.Tensor
    covars: torch.Tensor
    opacities: torch.Tensor
    rgb: torch.Tensor

    def __post_init__(self):
        C, M = self.means.shape[:2]
        for name, shape in (("means", (C, M, 3)), ("covars", (C, M, 3, 3)), ("opacities", (C, M)), ("rgb", (C, M, 3))):
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(f"CameraGaussians.{name}: expected {shape}, got {tuple(getattr(self, name).shape)}")

    def __len__(self) -> int:
        return self.means.shape[0]

    def rows(self, s: int, e: int) -> "CameraGaussians":
        """Cameras s:e (a render group)."""
        return CameraGaussians(self.means[s:e], self.covars[s:e], self.opacities[s:e], self.rgb[s:e])

    def rows_at(self, idx: torch.Tensor) -> "CameraGaussians":
        """Cameras idx `[n]` (the instances being reset)."""
        return CameraGaussians(self.means[idx], self.covars[idx], self.opacities[idx], self.rgb[idx])

    def to(self, device) -> "CameraGaussians":
        return CameraGaussians(self.means.to(device), self.covars.to(device), self.opacities.to(device),
                               self.rgb.to(device))

    def sh(self, K: int) -> torch.Tensor:
        """`[C, M, K, 3]` SH coefficients of the constant colours (degree 0 term only), to sit beside a scene's."""
        out = self.rgb.new_zeros(*self.rgb.shape[:2], K, 3)
        out[:, :, 0] = (self.rgb - 0.5) / SH_C0
        return out


def append_per_camera(means, covars, opac, sh, extra: CameraGaussians | None):
    """Per-camera rows `[C, N, ...]` with `extra`'s rows appended (`[C, N + M, ...]`); unchanged when None."""
    if extra is None:
        return means, covars, opac, sh
    if len(extra) != means.shape[0]:
        raise ValueError(f"render: extra Gaussians for {len(extra)} cameras, rendering {means.shape[0]}")
    dt = means.dtype
    return (torch.cat([means, extra.means.to(dt)], 1), torch.cat([covars, extra.covars.to(covars.dtype)], 1),
            torch.cat([opac, extra.opacities.to(opac.dtype)], 1), torch.cat([sh, extra.sh(sh.shape[2]).to(sh.dtype)], 1))


def append_pairs(cam, means, covars, opac, sh, extra: CameraGaussians | None):
    """Rows `[P, ...]` seen by camera `cam [P]` (grouped by camera) with `extra`'s rows appended to their
    cameras: -> (cam, means, covars, opacities, sh), still grouped by camera; unchanged when None."""
    if extra is None:
        return cam, means, covars, opac, sh
    C, M = extra.means.shape[:2]
    ecam = torch.arange(C, device=cam.device).repeat_interleave(M)
    order = torch.argsort(torch.cat([cam, ecam]), stable=True)
    cat = lambda a, b: torch.cat([a, b.reshape((C * M,) + a.shape[1:]).to(a.dtype)]).index_select(0, order)  # noqa: E731
    return (torch.cat([cam, ecam]).index_select(0, order), cat(means, extra.means), cat(covars, extra.covars),
            cat(opac, extra.opacities), cat(sh, extra.sh(sh.shape[1])))
