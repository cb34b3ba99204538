"""A Gaussian hierarchy and its per-view cut: level of detail whose cost is bounded by the image.

Why: a small camera cannot resolve most of a large splat, yet dropping splats (a top-k subset) deletes
whole surfaces. Following the hierarchical 3DGS idea (Kerbl et al. 2024; Octree-GS and CityGaussian cut
octree levels the same way), Gaussians are merged bottom-up into a tree whose every interior node is the
moment-matched merge of its children, and each view renders the coarsest nodes that project to at most
`target_px` pixels. A 32-px camera then sees a faithful blur of the whole scene, and the work per view
follows its pixels, not the scene's size.

Tree: node ids `0..N-1` are the splat's Gaussians (the leaves, in file order), `N..T-1` the interior
nodes, level by level, the root last. The levels are an octree over the splat's bounding cube (cells
are Morton-code prefixes): a node merges the items of one cell, so siblings lie within one cube and a
node's extent is bounded by its cell and its children's extents. Every node carries a bounding sphere
that contains its children's spheres (leaves: 3.33 standard deviations, the renderer's own extent), so
"too big to merge" and "visible" are monotone down the tree and a breadth-first descent finds the cut.

Merge of children i with activated opacity a_i and footprint area A_i (pi * product of the two largest
standard deviations): weights w_i = a_i A_i; mean and covariance by moment matching
(mu = sum w mu_i / W, Sigma = sum w (Sigma_i + d_i d_i^T) / W); SH coefficients weighted alike (they are
linear in colour); opacity W / A (at most `OPACITY_MAX`), so that the parent, seen from afar, carries the
opacity mass its children carry. That opacity may exceed 1: the renderer caps each pixel's alpha (0.999),
so a dense merge (children that overlap, as the Gaussians of a surface do) draws as a flat-topped footprint,
opaque out to where its children end and falling off only at their edge. Capped at 1, the same merge is a
Gaussian bump whose tails leave see-through seams where neighbouring merges meet (and a thinner, darker
surface at a distance).

The cut is not by size alone: each merged node carries `lod_scale`, its merge error (the colour spread of
the leaves below it, plus how much more opaque its children are than itself) in units of `LOD_ERROR_REF`,
clamped to `LOD_SCALE_RANGE`, and the cut compares size x lod_scale with the target. A uniform patch is
cut by its size, a textured one or an edge finer; the cost stays bounded by the image (at most the cut at
target / LOD_SCALE_RANGE[1]). Letting uniform patches grow coarser than the target (a lower bound of 0.5)
saved a quarter to a third of the Gaussians but cost 2.7-7.8 dB on a paper-size district's views
(experiments/render/README.md, Result 5).
"""

from __future__ import annotations

import logging
import os
import zipfile
import zlib
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.geometry import rotmat_to_quat

from .gaussians import Gaussians
from .packed import RADIUS_SIGMAS
from .sh import SH_C0

log = logging.getLogger(__name__)

FORMAT_VERSION = 4
MERGE_CHUNK = 1 << 16  # parents merged per batched step (bounds the [children, K, 3] temporaries)
START_NODES = 256  # each view's descent starts at the largest level of at most this many nodes
LOD_ERROR_REF = 0.05  # RGB standard deviation (plus opacity defect) of a merge at which the cut takes its size as is
LOD_SCALE_RANGE = (1.0, 2.0)  # the cut's size multipliers: uniform merges project to the target, varied ones to 1/2
OPACITY_MAX = 8.0  # a merged node's opacity may exceed 1 (see the module docstring: the flat-topped footprint)
CULL_MARGIN_PX = 4.0  # the frustum is widened by this many pixels: the renderer's eps2d blur and +1 px bound


@dataclass
class InteriorNodes:
    """The merged nodes (ids N..T-1) and the tree's structure; what the cache file stores.

    means [I, 3], covars [I, 3, 3], opacities [I] (activated), sh [I, K, 3]; radius [T] (every node's
    bounding sphere); child_ptr [I + 1] and child_ids [T - 1]: interior node j's children are
    child_ids[child_ptr[j]:child_ptr[j + 1]].
    """

    means: torch.Tensor
    covars: torch.Tensor
    opacities: torch.Tensor
    sh: torch.Tensor
    radius: torch.Tensor
    child_ptr: torch.Tensor
    child_ids: torch.Tensor
    lod_scale: torch.Tensor

    def to(self, device) -> "InteriorNodes":
        return InteriorNodes(*(getattr(self, f.name).to(device) for f in fields(self)))


class GaussianHierarchy:
    """The leaves (a `Gaussians`) plus their `InteriorNodes`; `cut` picks nodes per view, `gather` reads them."""

    def __init__(self, leaves: Gaussians, nodes: InteriorNodes, target_px: float = 1.0):
        if not target_px >= 0:
            raise ValueError(f"GaussianHierarchy: target_px must be >= 0 (pixels), got {target_px}")
        self.leaves, self.nodes, self.target_px = leaves, nodes, float(target_px)
        self.num_leaves = len(leaves)
        self.root = self.num_leaves + nodes.means.shape[0] - 1 if nodes.means.shape[0] else 0
        self._start: torch.Tensor | None = None
        self._node_means_t: torch.Tensor | None = None
        self._leaf_opacities = leaves.opacities.detach()

    def __len__(self) -> int:
        """The splat's Gaussians (the leaves), as `len(Gaussians)`; `num_nodes` counts the merged ones too."""
        return self.num_leaves

    def _tensors(self) -> list[torch.Tensor]:
        """Every tensor the hierarchy holds (the leaves' parameters, then the merged nodes')."""
        return self.leaves._tensors() + [getattr(self.nodes, f.name) for f in fields(self.nodes)]

    @property
    def num_nodes(self) -> int:
        return self.num_leaves + self.nodes.means.shape[0]

    def start_nodes(self, most: int = START_NODES) -> torch.Tensor:
        """Where each view's descent starts: the cut below the root expanded level by level while it holds
        at most `most` nodes. Views expand those top levels anyway whenever they need detail; a view that
        would stop above them gets this cut instead (finer, never coarser)."""
        if self._start is None:
            N, frontier = self.num_leaves, torch.tensor([self.root], device=self.nodes.radius.device)
            while bool((frontier >= N).any()):
                inner = frontier >= N
                _, kids = self._children(frontier[inner], frontier[inner] - N)
                nxt = torch.cat([frontier[~inner], kids])
                if nxt.numel() > most:
                    break
                frontier = nxt
            self._start = frontier
        return self._start

    @property
    def device(self) -> torch.device:
        return self.leaves.device

    @property
    def sh_degree(self) -> int:
        return self.leaves.sh_degree

    def to(self, device) -> "GaussianHierarchy":
        return GaussianHierarchy(self.leaves.to(device), self.nodes.to(device), self.target_px)

    def with_target(self, target_px: float) -> "GaussianHierarchy":
        """The same tree, cut at another projected size (pixels)."""
        return GaussianHierarchy(self.leaves, self.nodes, target_px)

    @torch.no_grad()
    def gather(self, ids: torch.Tensor):
        """Activated parameters of nodes `ids [M]`: means [M,3], covars [M,3,3], opacities [M], sh [M,K,3].
        Leaves and merged nodes live in separate tables, so the rows are split once by position (index
        lists, not boolean masks: one `nonzero` each) and each table is read with one index_select."""
        N, g, n = self.num_leaves, self.leaves, self.nodes
        leaf = ids < N
        at_leaf, at_node = leaf.nonzero().squeeze(1), (~leaf).nonzero().squeeze(1)
        li, ni = ids.index_select(0, at_leaf), ids.index_select(0, at_node) - N
        M, K = ids.shape[0], n.sh.shape[1]
        means = self.node_means_t().index_select(1, ids).t().to(g.means.dtype).contiguous()
        covars = g.means.new_empty(M, 3, 3)
        opac = g.means.new_empty(M)
        sh = g.means.new_empty(M, K, 3)
        covars.index_copy_(0, at_leaf, g.covariances().index_select(0, li))
        covars.index_copy_(0, at_node, n.covars.index_select(0, ni))
        opac.index_copy_(0, at_leaf, self._leaf_opacities.index_select(0, li))
        opac.index_copy_(0, at_node, n.opacities.index_select(0, ni))
        sh[:, 0].index_copy_(0, at_leaf, g.sh_dc.detach().index_select(0, li))
        if K > 1:
            sh[:, 1:].index_copy_(0, at_leaf, g.sh_rest.detach().index_select(0, li))
        sh.index_copy_(0, at_node, n.sh.index_select(0, ni))
        return means, covars, opac, sh

    def node_means_t(self) -> torch.Tensor:
        """Centres of every node as coordinate rows `[3, T]` (leaves then merged nodes) in the spheres' dtype:
        the cut and `gather` read them with one index per call. Built on first use (12 bytes per node)."""
        if self._node_means_t is None or self._node_means_t.device != self.nodes.radius.device:
            dtype = self.nodes.radius.dtype
            self._node_means_t = torch.cat([self.leaves.means.detach().to(dtype), self.nodes.means.to(dtype)]).t().contiguous()
        return self._node_means_t

    @torch.no_grad()
    def as_gaussians(self, ids: torch.Tensor) -> Gaussians:
        """Nodes `ids [M]` as raw `Gaussians` (covariances factored into rotation and log-scales): a cut
        saved as a PLY, or handed to code that takes plain Gaussians, renders as the cut does, except for merged
        nodes of opacity above 1 (`OPACITY_MAX`), which a logit cannot hold: they are clamped to 1, with a warning
        that counts them."""
        means, covars, opac, sh = self.gather(ids)
        dense = int((opac > 1).sum())
        if dense:
            log.warning("as_gaussians: %d of %d nodes have opacity above 1 (dense merges); clamped to 1", dense,
                        opac.numel())
        ev, vec = torch.linalg.eigh(covars.double())  # ascending eigenvalues, orthonormal columns
        vec[..., 2] *= torch.linalg.det(vec).sign()[:, None]  # a proper rotation
        quats = rotmat_to_quat(vec).to(means.dtype)
        log_scales = (0.5 * torch.log(ev.clamp_min(1e-30))).to(means.dtype)
        logits = torch.logit(opac.clamp(1e-7, 1 - 1e-7))
        return Gaussians(means, log_scales, quats, logits, sh[:, 0].contiguous(), sh[:, 1:].contiguous())

    @torch.no_grad()
    def cut(self, viewmats: torch.Tensor, Ks: torch.Tensor, width: int, height: int, target_px: float,
            *, near_plane: float = 0.01, camera_model: str = "pinhole") -> tuple[torch.Tensor, torch.Tensor]:
        """Per camera, the coarsest visible nodes whose bounding sphere projects to at most `target_px`
        pixels (radius); leaves wherever nothing coarser is small enough. -> (camera [M], node [M]),
        grouped by camera. viewmats [C, 4, 4] cam_from_world, Ks [C, 3, 3].

        `target_px = 0` yields every leaf that can touch the image (the renderer culls the rest alike).
        Interior nodes are culled on their spheres against the frustum widened by `CULL_MARGIN_PX`
        (pinhole only; other models cull behind the near plane only)."""
        N, n = self.num_leaves, self.nodes
        pinhole = camera_model == "pinhole"
        table = _camera_table(viewmats.to(n.radius.dtype), Ks.to(n.radius.dtype), width, height)  # [21, C]
        means_t, radius = self.node_means_t(), n.radius
        start = self.start_nodes().to(viewmats.device)
        cam = torch.arange(viewmats.shape[0], device=viewmats.device).repeat_interleave(start.numel())
        node = start.repeat(viewmats.shape[0])
        picked_cam, picked_node = [], []
        while cam.numel():
            # [k, P] rows (contiguous, one gather each): the camera's table, the node's centre and radius
            c, m, r = table.index_select(1, cam), means_t.index_select(1, node), radius.index_select(0, node)
            s = n.lod_scale.index_select(0, node)
            x, y, z = (c[3 * i] * m[0] + c[3 * i + 1] * m[1] + c[3 * i + 2] * m[2] + c[9 + i] for i in range(3))
            dist = torch.sqrt(x * x + y * y + z * z)
            visible = z + r >= near_plane
            if pinhole:  # the four widened side planes; radial magnification f d / z^2 off-axis, at the nearest depth
                for i, coord in enumerate((x, x, y, y)):
                    visible &= (c[13 + i] * coord - c[17 + i] * z) <= r
                size = c[12] * r * dist / (z.clamp_min(1e-6) * (z - r).clamp_min(1e-6))
                close = z - r <= near_plane
            else:
                size = c[12] * r / (dist - r).clamp_min(1e-6)
                close = dist - r <= near_plane
            expand = visible & (node >= N) & (close | (size * s > target_px))
            keep = (visible & ~expand).nonzero().squeeze(1)
            picked_cam.append(cam.index_select(0, keep))
            picked_node.append(node.index_select(0, keep))
            grow = expand.nonzero().squeeze(1)
            cam, node = self._children(cam.index_select(0, grow), node.index_select(0, grow) - N)
        cam, node = torch.cat(picked_cam), torch.cat(picked_node)
        order = torch.argsort(cam, stable=True)
        return cam[order], node[order]

    def _children(self, cam: torch.Tensor, interior: torch.Tensor):
        """(camera, child) pairs for every child of the interior nodes `interior [P]` (ids minus N)."""
        ptr = self.nodes.child_ptr
        start, count = ptr[interior], ptr[interior + 1] - ptr[interior]
        total = int(count.sum())
        first = torch.repeat_interleave(start - (torch.cumsum(count, 0) - count), count, output_size=total)
        pos = first + torch.arange(total, device=cam.device)
        return torch.repeat_interleave(cam, count, output_size=total), self.nodes.child_ids.index_select(0, pos)


def _camera_table(viewmats: torch.Tensor, Ks: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Per camera, what the cut's tests read, as rows `[21, C]` (gathered per node as contiguous rows):
    0-8 R (row-major) and 9-11 t of cam_from_world; 12 the larger focal length; 13-20 the pinhole frustum's
    side planes widened by `CULL_MARGIN_PX` pixels, as (a_k, b_k) with a_k = s/sqrt(1+tan^2) and
    b_k = tan/sqrt(1+tan^2): a sphere (camera-frame centre x, y, z; radius r) meets the frustum iff
    a_k coord_k - b_k z <= r for all four (x, x, y, y; each plane passes through the optical centre)."""
    fx, fy, cx, cy = Ks[:, 0, 0], Ks[:, 1, 1], Ks[:, 0, 2], Ks[:, 1, 2]
    m = CULL_MARGIN_PX
    tans = torch.stack([(width - cx + m) / fx, (cx + m) / fx, (height - cy + m) / fy, (cy + m) / fy])  # [4, C]
    inv = torch.rsqrt(1 + tans * tans)
    sign = torch.tensor([1.0, -1.0, 1.0, -1.0], dtype=tans.dtype, device=tans.device)[:, None]
    C = viewmats.shape[0]
    return torch.cat([viewmats[:, :3, :3].reshape(C, 9).t(), viewmats[:, :3, 3].t(), torch.maximum(fx, fy)[None],
                      sign * inv, tans * inv]).contiguous()


# ---- building ------------------------------------------------------------------------------------

MORTON_BITS = 21  # per axis: 63-bit codes


def morton_codes(means: torch.Tensor) -> torch.Tensor:
    """63-bit Z-order codes `[N]` (int64) of `means [N, 3]` on a cubic grid over their bounding box, so
    that a code prefix of 3 l bits names a cube (an octree cell) of side `extent / 2^l`."""
    lo = means.min(0).values
    extent = float((means.max(0).values - lo).max().clamp_min(1e-12))
    top = 2**MORTON_BITS - 1
    q = ((means - lo) / extent * top).round().long().clamp_(0, top)

    def spread(v: torch.Tensor) -> torch.Tensor:  # insert two zero bits between each of 21 bits
        v = (v | (v << 32)) & 0x1F00000000FFFF
        v = (v | (v << 16)) & 0x1F0000FF0000FF
        v = (v | (v << 8)) & 0x100F00F00F00F00F
        v = (v | (v << 4)) & 0x10C30C30C30C30C3
        return (v | (v << 2)) & 0x1249249249249249

    return spread(q[:, 0]) | (spread(q[:, 1]) << 1) | (spread(q[:, 2]) << 2)


def _area(covars: torch.Tensor) -> torch.Tensor:
    """pi x product of the two largest standard deviations of `covars [..., 3, 3]` (the footprint seen face-on)."""
    ev = torch.linalg.eigvalsh(covars.double()).clamp_min(0).to(covars.dtype)  # ascending
    return torch.pi * torch.sqrt(ev[..., 1] * ev[..., 2])


def lod_scales(spread: torch.Tensor, defect: torch.Tensor) -> torch.Tensor:
    """What the cut multiplies a merged node's projected size by: its merge error in units of `LOD_ERROR_REF`,
    clamped to `LOD_SCALE_RANGE`. spread: the RGB standard deviation (per channel, DC colour) of every leaf
    below the node, weighted as the merge weights them; defect: how much more opaque the children are on
    average than the merged node (a node that cannot cover what they cover: the see-through seams between
    merged nodes). The cut takes a uniform patch (a plain wall, the ground) at `LOD_SCALE_RANGE[0]` times its
    size and a textured one (window frames on a facade, an edge) at up to `LOD_SCALE_RANGE[1]` times, so that
    one is drawn finer."""
    return ((spread + defect) / LOD_ERROR_REF).clamp(*LOD_SCALE_RANGE)


def _merge(rows, group: torch.Tensor, P: int):
    """Merge the children `rows` (means [n,3], covars [n,3,3], opacities [n], sh [n,K,3], radius [n], colour
    variance [n]) into `P` parents; `group [n]` (sorted) is each child's parent. -> the parents' rows, in the
    same layout, and their `lod_scales` [P]."""
    means, covars, opac, sh, radius, cvar = rows
    mass = opac * _area(covars)  # [n]
    seg = lambda x: x.new_zeros((P,) + x.shape[1:]).index_add_(0, group, x)  # noqa: E731  segment sums
    W = seg(mass)
    flat = (W <= 0)[group]  # all children transparent or flat: equal weights
    w = torch.where(flat, torch.ones_like(mass), mass)
    w = w / seg(w)[group]
    mu = seg(w[:, None] * means)
    d = means - mu[group]
    cov = seg(w[:, None, None] * (covars + d[:, :, None] * d[:, None, :]))
    sh_p = seg(w[:, None, None] * sh)
    alpha = (W / _area(cov).clamp_min(1e-20)).clamp(max=OPACITY_MAX)
    rad = radius.new_zeros(P).scatter_reduce_(0, group, d.norm(dim=-1) + radius, "amax")
    dev = sh[:, 0] - sh_p[group, 0]
    cvar_p = seg(w * (cvar + (dev * dev).sum(-1)))  # the DC colour's variance over every leaf below, 3 channels
    spread = SH_C0 * torch.sqrt(cvar_p / 3)
    defect = (seg(w * opac) - alpha).clamp_min(0)
    return (mu, cov, alpha, sh_p, rad, cvar_p), lod_scales(spread, defect)


@torch.no_grad()
def build_hierarchy(gaussians: Gaussians, target_px: float = 1.0) -> GaussianHierarchy:
    """Merge `gaussians` bottom-up along an octree: level l's nodes are the cubes of side extent / 2^(21-l)
    (Morton-code prefixes) holding two or more items of the level below; a cube with one item passes it up
    unchanged. Batched per level; `MERGE_CHUNK` parents merged at a time bounds the temporaries."""
    g = gaussians.detach()
    N = len(g)
    if N == 0:
        raise ValueError("build_hierarchy: the splat has no Gaussians")
    leaf_radius = RADIUS_SIGMAS * g.scales.max(-1).values
    leaf_cov, leaf_opac = g.covariances(), g.opacities
    code = morton_codes(g.means)
    order = torch.argsort(code, stable=True)
    items, code = order, code[order]  # the current level's node ids in Morton order, and their cells' codes
    levels: list[tuple] = []  # rows (means, covars, opacities, sh, radius, colour variance) and lod scales of each level's new nodes
    child_runs: list[torch.Tensor] = []  # per level: the children of its new nodes, in parent order
    counts: list[torch.Tensor] = []  # per level: children per new node
    next_id = N

    leaf_cvar = g.means.new_zeros(N)

    def rows(ids: torch.Tensor):
        """Rows of node ids (leaves and earlier levels' nodes, mixed) in the merge layout."""
        leaf = ids < N
        parts = [(leaf, ids[leaf], (g.means, leaf_cov, leaf_opac, None, leaf_radius, leaf_cvar))]
        first = N
        for lv in levels:  # each earlier level's new nodes hold a contiguous id range
            m = (ids >= first) & (ids < first + lv[0].shape[0])
            parts.append((m, ids[m] - first, lv))
            first += lv[0].shape[0]
        n, K = ids.shape[0], g.sh_rest.shape[1] + 1
        out = [g.means.new_empty(n, 3), g.means.new_empty(n, 3, 3), g.means.new_empty(n), g.means.new_empty(n, K, 3),
               g.means.new_empty(n), g.means.new_empty(n)]
        for mask, local, src in parts:
            if not bool(mask.any()):
                continue
            for i in range(6):
                if i == 3 and src[3] is None:  # leaf SH: DC and rest are stored apart
                    out[3][mask] = torch.cat([g.sh_dc[local, None], g.sh_rest[local]], 1)
                else:
                    out[i][mask] = src[i][local]
        return out

    for _ in range(MORTON_BITS):
        if items.numel() == 1:
            break
        cell = code >> 3  # the parent cube of each item's cell
        _, size = torch.unique_consecutive(cell, return_counts=True)
        start = torch.cumsum(size, 0) - size
        multi = size > 1
        if not bool(multi.any()):
            code = cell
            continue
        # the children of this level's new nodes: the items of the multi-item cells, in order
        in_multi = torch.repeat_interleave(multi, size)
        kids = items[in_multi]
        P = int(multi.sum())
        group = torch.repeat_interleave(torch.arange(P), size[multi])
        parts, bounds = [], torch.cat([torch.searchsorted(group, torch.arange(0, P, MERGE_CHUNK)), torch.tensor([kids.numel()])])
        for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
            gi = group[a:b]
            parts.append(_merge(rows(kids[a:b]), gi - gi[0], int(gi[-1] - gi[0]) + 1))
        levels.append(tuple(torch.cat([p[0][i] for p in parts]) for i in range(6)) + (torch.cat([p[1] for p in parts]),))
        child_runs.append(kids)
        counts.append(size[multi])
        new_ids = torch.full_like(size, -1)
        new_ids[multi] = torch.arange(next_id, next_id + P)
        new_ids[~multi] = items[start[~multi]]  # single items pass up unchanged
        next_id += P
        items, code = new_ids, cell[start]
    cat = lambda i, empty: torch.cat([lv[i] for lv in levels]) if levels else empty  # noqa: E731
    K = g.sh_rest.shape[1] + 1
    nodes = InteriorNodes(
        means=cat(0, g.means.new_zeros(0, 3)), covars=cat(1, g.means.new_zeros(0, 3, 3)),
        opacities=cat(2, g.means.new_zeros(0)), sh=cat(3, g.means.new_zeros(0, K, 3)),
        radius=torch.cat([leaf_radius, cat(4, g.means.new_zeros(0))]),
        child_ptr=torch.cat([torch.zeros(1, dtype=torch.long), torch.cumsum(torch.cat(counts), 0)]) if counts
        else torch.zeros(1, dtype=torch.long),
        child_ids=torch.cat(child_runs) if child_runs else torch.zeros(0, dtype=torch.long),
        lod_scale=torch.cat([g.means.new_ones(N), cat(6, g.means.new_zeros(0))]))
    return GaussianHierarchy(gaussians, nodes, target_px)


# ---- the cache beside the splat ---------------------------------------------------------------------

def save_nodes(path: Path, nodes: InteriorNodes, *, source_sha256: str) -> None:
    """Write `nodes` as an uncompressed npz, atomically, with the splat's hash and the build settings."""
    arrays = {f.name: getattr(nodes, f.name).cpu().numpy() for f in fields(nodes)}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays, source_sha256=np.array(source_sha256),
                     format_version=np.array(FORMAT_VERSION))


def load_nodes(path: Path, *, source_sha256: str) -> InteriorNodes | None:
    """The cached nodes when `path` holds a hierarchy of this splat (same hash and format); else None."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["source_sha256"]) != source_sha256 or int(z["format_version"]) != FORMAT_VERSION:
                return None
            return InteriorNodes(*(torch.from_numpy(np.array(z[f.name])) for f in fields(InteriorNodes)))
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        # truncated, empty, bit-flipped (a member's CRC) or foreign: a miss, rebuilt and replaced by the caller
        log.warning("%s: unreadable hierarchy cache (%s: %s); rebuilding it", path, type(e).__name__, e)
        return None
