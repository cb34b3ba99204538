"""torch.compile'd hot stages of the fast path (inductor's C++ backend on CPU, Triton on GPU).

Why only these two: they are the elementwise-heavy stages that eager torch runs as dozens of
separate passes over memory (a block of the visible-pair EWA projection, and a chunk of the composite:
quadratic form -> alpha -> threshold -> transmittance -> weighted colour sum); inductor fuses each
into a few loops. The binning (sorts, nonzero) and the host-side chunk plan stay eager: they have
data-dependent shapes and are already single library calls. The eager functions remain the
reference (`packed.project_packed`, `rasterize.forward_chunk`) and the tests compare against them.

The backward always runs eagerly (`_RasterizeFn.backward` recomputes chunks itself); autograd
through the compiled projection goes through AOTAutograd. If compilation is unavailable or fails
(no C++ compiler, an unsupported op), the stage falls back to eager for the rest of the process,
with a single warning.
"""

from __future__ import annotations

import warnings

import torch

from .packed import _project_pairs, project_packed
from .rasterize import forward_chunk

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
forward_chunk_compiled = CompiledStage(forward_chunk)


def project_packed_compiled(*args, **kwargs):
    """`packed.project_packed` with its per-block EWA stage compiled: the candidate cull (`nonzero`)
    and the host-side block loop stay eager, so the compiled graph sees fixed-size blocks only."""
    return project_packed(*args, pair_fn=project_pairs_compiled, **kwargs)
