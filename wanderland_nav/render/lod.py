"""Level of detail: the `max_gaussians` splats that matter most, for CPU-speed training and evaluation.

Why: the pure-torch rasteriser's cost grows with the Gaussians per tile; on a 2-core CPU the full tiny
demo (54k) renders ~1 agent-frame/s, a 10k subset several times faster with the same layout and
colours. Training, evaluation and replay use this one selection, so their numbers and images agree.
"""

from __future__ import annotations

import logging

import torch

from wanderland_nav.render.gaussians import Gaussians

log = logging.getLogger(__name__)


def lod_subset(gaussians: Gaussians, max_gaussians: int | None) -> Gaussians:
    """`gaussians`, or the `max_gaussians` with the largest opacity x footprint
    (sigmoid(opacity) * exp(sum of the two largest log-scales)), in their original order. None keeps all."""
    if max_gaussians is None or len(gaussians) <= int(max_gaussians):
        return gaussians
    g = gaussians
    score = torch.sigmoid(g.opacity_logits.view(-1)) * torch.exp(g.log_scales.topk(2, dim=-1).values.sum(-1))
    keep = score.topk(int(max_gaussians)).indices.sort().values
    log.info("rendering %d of %d Gaussians (max_gaussians)", len(keep), len(g))
    return g[keep]
