"""torch.compile'd hot stage of the fast path (inductor's C++ backend on CPU, Triton on GPU).

What is compiled: the EWA block of the packed projection (`packed._project_pairs`: Jacobian,
J R Sigma R^T J^T, blur, inverse, radii, for a fixed-size block of candidate pairs), which eager
torch runs as ~120 separate passes; inductor fuses them (B=64 env poses, 32x32, 10k Gaussians:
62 -> 37 CPU ms for the whole projection, 26 s to compile). The candidate cull (`nonzero`), the
binning (sorts) and the host-side block and chunk loops stay eager: data-dependent shapes.

What is not, and why (measured 2026-11-24, 1 thread): the composite chunk (`rasterize.forward_chunk`)
compiled with dynamic shapes ran 2.3x *slower* than eager (3.7 vs 1.6 ms per 131k pixel-entry
evaluations, 318 s to compile), and a fully fused, unrolled front-to-back kernel no faster than
eager; the eager chunk kernel is used in both modes. The eager functions remain the reference and
the tests compare against them.

Autograd through the compiled block goes through AOTAutograd. If compilation is unavailable or
fails (no C++ compiler, an unsupported op), the stage falls back to eager for the rest of the
process, with a single warning.
"""

from __future__ import annotations

import warnings

import torch

from .packed import _project_pairs, project_packed

_warned = False


class CompiledStage:
    """`fn` through torch.compile(dynamic=True) on first use; eager for good after any failure."""

    def __init__(self, fn):
        self.eager = fn
        self.compiled = None
        self.failed = False

    def __call__(self, *args, **kwargs):
        if not self.failed:
            try:
                if self.compiled is None:
                    self.compiled = torch.compile(self.eager, dynamic=True)
                return self.compiled(*args, **kwargs)
            except Exception as err:  # noqa: BLE001  any compiler/backend failure means: run eagerly
                self.failed = True
                _warn_once(f"{self.eager.__name__}: {type(err).__name__}: {str(err).splitlines()[0][:200]}")
        return self.eager(*args, **kwargs)


def _warn_once(msg: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(f"render: torch.compile unavailable, using the eager renderer ({msg})", RuntimeWarning,
                      stacklevel=3)


project_pairs_compiled = CompiledStage(_project_pairs)


def project_packed_compiled(*args, **kwargs):
    """`packed.project_packed` with its per-block EWA stage compiled: the candidate cull (`nonzero`)
    and the host-side block loop stay eager, so the compiled graph sees fixed-size blocks only."""
    return project_packed(*args, pair_fn=project_pairs_compiled, **kwargs)
