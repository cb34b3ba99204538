"""`Gaussians`: raw 3DGS parameters and INRIA PLY load/save.

Parameters are kept *raw*, exactly as the INRIA 3DGS PLY stores them (log scales, logit
opacities, unnormalised wxyz quaternions, SH coefficients with the DC term separate), so that a
load/save round trip is lossless and optimisers act on the unconstrained values. Activation
happens in `render()` (exp, sigmoid, normalise) via the `scales` / `opacities` properties.

PLY layout (read by property name, any order): `x y z`, optional `nx ny nz` (ignored),
`f_dc_0..2`, `f_rest_0..M-1` channel-major (all R coefficients, then G, then B; M = 3*(K-1),
K = (degree+1)^2 with degree 0..3), `opacity` (logit), `scale_0..2` (log), `rot_0..3` (wxyz).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

from .ply import PlyError, read_ply_element
from .plyio import write_ply_chunks
from .projection import quat_scale_to_covar

# |logit| bound applied to non-finite opacities: sigmoid(±20) is 1 - 2e-9 / 2e-9, i.e. fully opaque /
# transparent in float32, while keeping a finite value (and a non-zero gradient) for training.
OPACITY_LOGIT_CLIP = 20.0
SAVE_CHUNK = 1 << 18  # rows per block of `Gaussians.save` (a 65 MB table of SH-3 rows)

_REST_COUNT_TO_DEGREE = {3 * ((d + 1) ** 2 - 1): d for d in range(4)}  # 0->0, 9->1, 24->2, 45->3


def sh_degree_from_coeffs(num_coeffs: int) -> int:
    """K = (degree+1)^2 SH coefficients per channel -> degree (0..3); raises for any other K."""
    d = int(round(math.sqrt(num_coeffs))) - 1
    if d < 0 or d > 3 or (d + 1) ** 2 != num_coeffs:
        raise ValueError(f"{num_coeffs} SH coefficients per channel is not (degree+1)^2 for degree 0..3")
    return d


@dataclass
class Gaussians:
    """N Gaussians in the scene frame with raw (unactivated) parameters.

    means          [N, 3]       scene-frame centres (metres)
    log_scales     [N, 3]       log of the per-axis standard deviations
    quats          [N, 4]       wxyz rotation, not necessarily normalised
    opacity_logits [N]          logit of the opacity
    sh_dc          [N, 3]       degree-0 SH coefficient per RGB channel
    sh_rest        [N, K-1, 3]  higher SH coefficients (K = (degree+1)^2; K-1 = 0 for degree 0)
    """

    means: torch.Tensor
    log_scales: torch.Tensor
    quats: torch.Tensor
    opacity_logits: torch.Tensor
    sh_dc: torch.Tensor
    sh_rest: torch.Tensor

    def __post_init__(self):
        n = self.means.shape[0] if self.means.dim() == 2 else -1
        expect = {"means": (n, 3), "log_scales": (n, 3), "quats": (n, 4), "opacity_logits": (n,), "sh_dc": (n, 3)}
        for name, shape in expect.items():
            t = getattr(self, name)
            if not isinstance(t, torch.Tensor) or tuple(t.shape) != shape or n < 0:
                got = tuple(t.shape) if isinstance(t, torch.Tensor) else type(t).__name__
                raise ValueError(f"Gaussians.{name}: expected shape {shape} (N from means [N,3]), got {got}")
        r = self.sh_rest
        if not isinstance(r, torch.Tensor) or r.dim() != 3 or r.shape[0] != n or r.shape[2] != 3:
            raise ValueError(f"Gaussians.sh_rest: expected [N, K-1, 3], got {tuple(getattr(r, 'shape', ()))}")
        try:
            sh_degree_from_coeffs(r.shape[1] + 1)
        except ValueError as e:
            raise ValueError(f"Gaussians.sh_rest: {e}") from None
        devices = {t.device for t in self._tensors()}
        if len(devices) != 1:
            raise ValueError(f"Gaussians: all tensors must be on one device, got {devices}")

    # ---- container protocol -------------------------------------------------------------
    def _tensors(self) -> list[torch.Tensor]:
        return [getattr(self, f.name) for f in fields(self)]

    def __len__(self) -> int:
        return self.means.shape[0]

    def __getitem__(self, idx) -> "Gaussians":
        """Select Gaussians by int/slice/bool mask/index tensor (keeps the N dimension)."""
        if isinstance(idx, int):
            idx = slice(idx, idx + 1 if idx != -1 else None)
        return Gaussians(*(t[idx] for t in self._tensors()))

    def to(self, *args, **kwargs) -> "Gaussians":
        """Like `Tensor.to`: device and/or dtype for every parameter."""
        return Gaussians(*(t.to(*args, **kwargs) for t in self._tensors()))

    def detach(self) -> "Gaussians":
        return Gaussians(*(t.detach() for t in self._tensors()))

    def requires_grad_(self, flag: bool = True) -> "Gaussians":
        for t in self._tensors():
            t.requires_grad_(flag)
        return self

    def parameters(self) -> dict[str, torch.Tensor]:
        """Name -> tensor, e.g. for per-group learning rates in an optimiser."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def device(self) -> torch.device:
        return self.means.device

    @property
    def dtype(self) -> torch.dtype:
        return self.means.dtype

    @property
    def sh_degree(self) -> int:
        return sh_degree_from_coeffs(self.sh_rest.shape[1] + 1)

    # ---- activated views (what the rasterizer consumes) ---------------------------------
    @property
    def scales(self) -> torch.Tensor:
        """[N, 3] standard deviations."""
        return self.log_scales.exp()

    @property
    def opacities(self) -> torch.Tensor:
        """[N] opacities in (0, 1)."""
        return torch.sigmoid(self.opacity_logits)

    @property
    def sh_coeffs(self) -> torch.Tensor:
        """[N, K, 3] all SH coefficients (DC first), gsplat's `colors` layout with `sh_degree`."""
        return torch.cat([self.sh_dc[:, None, :], self.sh_rest], dim=1)

    def covariances(self) -> torch.Tensor:
        """[N, 3, 3] world covariances R S S^T R^T (contiguous): what the renderer projects.

        Cached on this object while `quats` and `log_scales` are the same tensors at the same version
        and autograd would not track them: the simulator renders one fixed scene thousands of times
        (~1.7 ms per renderer call at 10k Gaussians, one thread, ~5 % of a 4-camera call). Whenever a
        gradient could flow it is recomputed and not cached, so training builds a fresh graph."""
        q, s = self.quats, self.log_scales
        if torch.is_grad_enabled() and (q.requires_grad or s.requires_grad):
            return quat_scale_to_covar(q, self.scales)
        hit = self.__dict__.get("_covariances")  # (quats, log_scales, their versions, covariances)
        if hit is not None and hit[0] is q and hit[1] is s and hit[2] == (q._version, s._version):
            return hit[3]
        cov = quat_scale_to_covar(q, self.scales).contiguous()
        self.__dict__["_covariances"] = (q, s, (q._version, s._version), cov)
        return cov

    # ---- PLY I/O ------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike, *, device: str | torch.device = "cpu",
             dtype: torch.dtype = torch.float32) -> "Gaussians":
        """Read an INRIA 3DGS PLY by property name (any order, normals optional, SH degree 0..3).

        `+-inf` opacity logits (some exporters write them for fully opaque splats) are clipped to
        `±OPACITY_LOGIT_CLIP` before any sigmoid; NaN anywhere, or non-finite values in other
        fields, raise `PlyError` naming the file and field.
        """
        path = Path(path)
        v = read_ply_element(path, "vertex")
        names = set(v.dtype.names)

        def take(props: list[str], field: str) -> np.ndarray:
            missing = [p for p in props if p not in names]
            if missing:
                raise PlyError(f"{path}: Gaussian PLY is missing property {missing} needed for {field}")
            # in the file's own float precision (float32 for every 3DGS exporter we know; the conversion to
            # float64 would be exact but doubles the memory: a paper-size splat's f_rest is 1.3 GB in float32)
            out = np.stack([v[p].astype(np.promote_types(v[p].dtype, np.float32), copy=False) for p in props],
                           axis=-1) if props else np.zeros((len(v), 0))
            if np.isnan(out).any():
                raise PlyError(f"{path}: {field} contains {int(np.isnan(out).sum())} NaN values")
            if field != "opacity" and not np.isfinite(out).all():
                raise PlyError(f"{path}: {field} contains {int((~np.isfinite(out)).sum())} infinite values")
            return out

        rest_names = [n for n in v.dtype.names if n.startswith("f_rest_")]
        idx = sorted(int(n[len("f_rest_"):]) for n in rest_names if n[len("f_rest_"):].isdigit())
        if len(idx) != len(rest_names) or idx != list(range(len(idx))):
            raise PlyError(f"{path}: f_rest_* properties must be numbered 0..M-1 without gaps, got {sorted(rest_names)}")
        if len(idx) not in _REST_COUNT_TO_DEGREE:
            raise PlyError(f"{path}: {len(idx)} f_rest_* properties; expected one of "
                           f"{sorted(_REST_COUNT_TO_DEGREE)} (SH degree 0..3, 3 channels)")
        k1 = len(idx) // 3
        means = take(["x", "y", "z"], "means (x, y, z)")
        log_scales = take(["scale_0", "scale_1", "scale_2"], "scales (scale_0..2)")
        quats = take(["rot_0", "rot_1", "rot_2", "rot_3"], "rotation (rot_0..3, wxyz)")
        opac = take(["opacity"], "opacity")[:, 0]
        opac = np.clip(opac, -OPACITY_LOGIT_CLIP, OPACITY_LOGIT_CLIP, out=opac, where=~np.isfinite(opac))
        sh_dc = take(["f_dc_0", "f_dc_1", "f_dc_2"], "sh_dc (f_dc_0..2)")
        rest = take([f"f_rest_{i}" for i in range(len(idx))], "sh_rest (f_rest_*)")
        sh_rest = rest.reshape(len(v), 3, k1).transpose(0, 2, 1)  # channel-major -> [N, K-1, 3]

        def t(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.ascontiguousarray(a), dtype=dtype, device=device)

        return cls(t(means), t(log_scales), t(quats), t(opac), t(sh_dc), t(sh_rest))

    def save(self, path: str | os.PathLike, chunk: int = SAVE_CHUNK) -> None:
        """Write the INRIA 3DGS PLY layout (float32, zero normals, channel-major f_rest), atomically, `chunk`
        rows at a time (the file is the same for any chunk; memory holds one chunk's table, not the splat's)."""
        n, k1 = len(self), self.sh_rest.shape[1]
        groups = [(["x", "y", "z"], lambda s: self.means[s]), (["nx", "ny", "nz"], None),
                  (["f_dc_0", "f_dc_1", "f_dc_2"], lambda s: self.sh_dc[s]),
                  ([f"f_rest_{i}" for i in range(3 * k1)], lambda s: self.sh_rest[s].transpose(1, 2)),  # channel-major
                  (["opacity"], lambda s: self.opacity_logits[s]), (["scale_0", "scale_1", "scale_2"], lambda s: self.log_scales[s]),
                  (["rot_0", "rot_1", "rot_2", "rot_3"], lambda s: self.quats[s])]
        dtype = np.dtype([(name, "<f4") for names, _ in groups for name in names])

        def tables():
            for a in range(0, n, chunk):
                s = slice(a, min(n, a + chunk))
                table = np.zeros(s.stop - s.start, dtype=dtype)
                for names, get in groups:
                    if get is None or not names:  # zero normals; no f_rest at SH degree 0
                        continue
                    arr = get(s).detach().to("cpu", torch.float32).numpy().reshape(-1, len(names))
                    for i, name in enumerate(names):
                        table[name] = arr[:, i]
                yield table

        write_ply_chunks(path, dtype, n, tables(), "vertex")
