"""A Gaussian hierarchy and its per-view cut: level of detail whose cost is bounded by the image.

Why: a small camera cannot resolve most of a large splat, yet dropping splats (a top-k subset) deletes
whole surfaces. Following the hierarchical 3DGS idea (Kerbl et al. 2024; Octree-GS and CityGaussian cut
octree levels the same way), Gaussians are merged bottom-up into a tree whose every interior node is the
moment-matched merge of its children, and each view renders the coarsest nodes that project to at most
`target_px` pixels. A 32-px camera then sees a faithful blur of the whole scene, and the work per view
follows its pixels, not the scene's size.

Tree: node ids `0..N-1` are the splat's Gaussians (the leaves, in file order), `N..T-1` the interior
nodes, level by level, the root last. Children are consecutive runs of a Morton (Z-order) sort of the
leaves, `fanout` per parent, so siblings are spatial neighbours. Every node carries a bounding sphere
that contains its children's spheres (leaves: 3.33 standard deviations, the renderer's own extent), so
"too big to merge" and "visible" are monotone down the tree and a breadth-first descent finds the cut.

Merge of children i with activated opacity a_i and footprint area A_i (pi * product of the two largest
standard deviations): weights w_i = a_i A_i; mean and covariance by moment matching
(mu = sum w mu_i / W, Sigma = sum w (Sigma_i + d_i d_i^T) / W); SH coefficients weighted alike (they are
linear in colour); opacity min(1, W / A) so that the parent, seen from afar, covers the area its
children cover.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

from .gaussians import Gaussians
from .packed import RADIUS_SIGMAS

FORMAT_VERSION = 1
MERGE_CHUNK = 1 << 16  # parents merged per batched step (bounds the [chunk, fanout, K, 3] temporaries)
START_NODES = 256  # each view's descent starts at the largest level of at most this many nodes
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
        self.fanout = int(nodes.child_ptr[1] - nodes.child_ptr[0]) if nodes.means.shape[0] else 2
        self._leaf_opacities = leaves.opacities.detach()

    def __len__(self) -> int:
        """The splat's Gaussians (the leaves), as `len(Gaussians)`; `num_nodes` counts the merged ones too."""
        return self.num_leaves

    @property
    def num_nodes(self) -> int:
        return self.num_leaves + self.nodes.means.shape[0]

    def start_nodes(self, most: int = START_NODES) -> torch.Tensor:
        """The largest level of at most `most` nodes:
        where each view's descent starts. The levels above it are expanded by any view close enough to
        need detail, so skipping them saves small steps per call; a view that would stop above it gets
        this level instead (finer, never coarser)."""
        sizes, n = [], self.num_leaves
        while n > 1:  # level sizes: ceil-divided by the fanout from the leaves up
            n = -(-n // self.fanout)
            sizes.append(n)
        first = self.num_leaves
        for size in sizes:
            if size <= most:
                return torch.arange(first, first + size, device=self.nodes.radius.device)
            first += size
        return torch.tensor([self.root], device=self.nodes.radius.device)

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
        """Activated parameters of nodes `ids [M]`: means [M,3], covars [M,3,3], opacities [M], sh [M,K,3]."""
        N, g, n = self.num_leaves, self.leaves, self.nodes
        leaf = ids < N
        li, ni = ids[leaf], ids[~leaf] - N
        M, K = ids.shape[0], n.sh.shape[1]
        means = g.means.new_empty(M, 3)
        covars = g.means.new_empty(M, 3, 3)
        opac = g.means.new_empty(M)
        sh = g.means.new_empty(M, K, 3)
        means[leaf], means[~leaf] = g.means.detach()[li], n.means[ni]
        covars[leaf], covars[~leaf] = g.covariances()[li], n.covars[ni]
        opac[leaf], opac[~leaf] = self._leaf_opacities[li], n.opacities[ni]
        sh[leaf] = torch.cat([g.sh_dc.detach()[li, None], g.sh_rest.detach()[li]], 1)
        sh[~leaf] = n.sh[ni]
        return means, covars, opac, sh

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
        C = viewmats.shape[0]
        R, t = viewmats[:, :3, :3].to(n.radius.dtype), viewmats[:, :3, 3].to(n.radius.dtype)
        f = torch.maximum(Ks[:, 0, 0], Ks[:, 1, 1]).to(n.radius.dtype)
        start = self.start_nodes().to(viewmats.device)
        cam = torch.arange(C, device=viewmats.device).repeat_interleave(start.numel())
        node = start.repeat(C)
        picked_cam, picked_node = [], []
        while cam.numel():
            leaf = node < N
            mu = torch.empty(node.shape[0], 3, dtype=n.radius.dtype, device=node.device)
            mu[leaf], mu[~leaf] = self.leaves.means.detach()[node[leaf]].to(mu.dtype), n.means[node[~leaf] - N]
            pc = torch.einsum("pij,pj->pi", R[cam], mu) + t[cam]  # [P, 3] camera frame
            r = n.radius[node]
            x, y, z = pc.unbind(-1)
            visible = z + r >= near_plane
            if camera_model == "pinhole":
                visible &= _inside_planes(x, y, z, r, Ks[cam].to(r.dtype), width, height)
            dist = pc.norm(dim=-1)
            if camera_model == "pinhole":  # radial magnification f d / z^2 off-axis, at the sphere's nearest depth
                size = f[cam] * r * dist / (z.clamp_min(1e-6) * (z - r).clamp_min(1e-6))
                close = z - r <= near_plane
            else:
                size = f[cam] * r / (dist - r).clamp_min(1e-6)
                close = dist - r <= near_plane
            expand = visible & ~leaf & (close | (size > target_px))
            keep = visible & ~expand
            picked_cam.append(cam[keep])
            picked_node.append(node[keep])
            cam, node = self._children(cam[expand], node[expand] - N)
        cam, node = torch.cat(picked_cam), torch.cat(picked_node)
        order = torch.argsort(cam, stable=True)
        return cam[order], node[order]

    def _children(self, cam: torch.Tensor, interior: torch.Tensor):
        """(camera, child) pairs for every child of the interior nodes `interior [P]` (ids minus N)."""
        ptr = self.nodes.child_ptr
        start, count = ptr[interior], ptr[interior + 1] - ptr[interior]
        total = int(count.sum())
        first = torch.repeat_interleave(start - (torch.cumsum(count, 0) - count), count)
        return torch.repeat_interleave(cam, count), self.nodes.child_ids[first + torch.arange(total, device=cam.device)]


def _inside_planes(x, y, z, r, Ks, width: int, height: int) -> torch.Tensor:
    """Sphere (centre x, y, z camera frame, radius r; [P] each) meets the pinhole frustum widened by
    `CULL_MARGIN_PX` pixels on each side: its signed distance to each side plane is below r."""
    fx, fy, cx, cy = Ks[:, 0, 0], Ks[:, 1, 1], Ks[:, 0, 2], Ks[:, 1, 2]
    m = CULL_MARGIN_PX
    ok = torch.ones_like(z, dtype=torch.bool)
    # plane through the optical centre: u = c + s * lim  <=>  a*z - s*x = 0 with a the tangent of the edge
    for coord, f, lo, hi in ((x, fx, cx + m, width - cx + m), (y, fy, cy + m, height - cy + m)):
        for tan, sign in ((hi / f, 1.0), (lo / f, -1.0)):
            ok &= (sign * coord - tan * z) / torch.sqrt(1 + tan * tan) <= r
    return ok


# ---- building ------------------------------------------------------------------------------------

def morton_order(means: torch.Tensor) -> torch.Tensor:
    """Indices that sort `means [N, 3]` along a 63-bit Z-order curve of their bounding box."""
    lo, hi = means.min(0).values, means.max(0).values
    q = ((means - lo) / (hi - lo).clamp_min(1e-12) * (2**21 - 1)).round().long().clamp_(0, 2**21 - 1)

    def spread(v: torch.Tensor) -> torch.Tensor:  # insert two zero bits between each of 21 bits
        v = (v | (v << 32)) & 0x1F00000000FFFF
        v = (v | (v << 16)) & 0x1F0000FF0000FF
        v = (v | (v << 8)) & 0x100F00F00F00F00F
        v = (v | (v << 4)) & 0x10C30C30C30C30C3
        return (v | (v << 2)) & 0x1249249249249249

    code = spread(q[:, 0]) | (spread(q[:, 1]) << 1) | (spread(q[:, 2]) << 2)
    return torch.argsort(code, stable=True)


def _area(covars: torch.Tensor) -> torch.Tensor:
    """pi x product of the two largest standard deviations of `covars [..., 3, 3]` (the footprint seen face-on)."""
    ev = torch.linalg.eigvalsh(covars.double()).clamp_min(0).to(covars.dtype)  # ascending
    return torch.pi * torch.sqrt(ev[..., 1] * ev[..., 2])


def _merge(means, covars, opac, sh, radius, valid):
    """Merge groups: inputs [P, k, ...] with `valid [P, k]`; -> parent means, covars, opacities, sh, radius."""
    w = opac * _area(covars) * valid
    none = w.sum(1, keepdim=True) <= 0  # all children transparent or flat: equal weights
    w = torch.where(none, valid.to(w.dtype), w)
    W = w.sum(1)  # [P]
    wn = w / W[:, None]
    mu = torch.einsum("pk,pki->pi", wn, means)
    d = means - mu[:, None]
    cov = torch.einsum("pk,pkij->pij", wn, covars + d[..., :, None] * d[..., None, :])
    sh_p = torch.einsum("pk,pkc->pc", wn, sh.flatten(2)).view(sh.shape[0], *sh.shape[2:])
    mass = (opac * _area(covars) * valid).sum(1)
    alpha = (mass / _area(cov).clamp_min(1e-20)).clamp(max=1.0)
    rad = torch.where(valid, d.norm(dim=-1) + radius, torch.zeros_like(radius)).max(1).values
    return mu, cov, alpha, sh_p, rad


@torch.no_grad()
def build_hierarchy(gaussians: Gaussians, fanout: int = 4, target_px: float = 1.0) -> GaussianHierarchy:
    """Merge `gaussians` bottom-up (batched per level, `MERGE_CHUNK` parents at a time) into a hierarchy."""
    if fanout < 2:
        raise ValueError(f"build_hierarchy: fanout must be >= 2, got {fanout}")
    g = gaussians.detach()
    N = len(g)
    if N == 0:
        raise ValueError("build_hierarchy: the splat has no Gaussians")
    leaf_radius = RADIUS_SIGMAS * g.scales.max(-1).values
    leaf_cov, leaf_opac = g.covariances(), g.opacities
    K = g.sh_rest.shape[1] + 1

    def leaf_rows(ids):
        return (g.means[ids], leaf_cov[ids], leaf_opac[ids], torch.cat([g.sh_dc[ids, None], g.sh_rest[ids]], 1),
                leaf_radius[ids])

    parts: list[tuple] = []  # per level: (means, covars, opacities, sh, radius) of its new nodes
    child_lists = []
    items = morton_order(g.means)  # the current level's node ids, in spatial order
    radius = [leaf_radius]
    rows = leaf_rows
    next_id = N
    while items.numel() > 1:
        P = -(-items.numel() // fanout)
        pad = torch.full((P * fanout - items.numel(),), -1, dtype=torch.long)
        groups = torch.cat([items, pad]).view(P, fanout)
        out = []
        for s in range(0, P, MERGE_CHUNK):
            ids = groups[s:s + MERGE_CHUNK]
            valid = ids >= 0
            ids = torch.where(valid, ids, ids[:, :1]).view(-1)  # padding reads the group's first child, weight 0
            m, c, a, h, r = rows(ids if rows is leaf_rows else ids - base)
            k = valid.shape
            out.append(_merge(m.view(*k, 3), c.view(*k, 3, 3), a.view(k), h.view(*k, K, 3), r.view(k), valid))
        level = tuple(torch.cat([o[i] for o in out]) for i in range(5))
        parts.append(level)
        radius.append(level[4])
        child_lists.append(items)
        base = next_id
        rows = (lambda lv: (lambda ids: tuple(x[ids] for x in lv)))(level)
        items = torch.arange(next_id, next_id + P)
        next_id += P
    cat = lambda i, empty: torch.cat([p[i] for p in parts]) if parts else empty  # noqa: E731
    counts = [torch.bincount(torch.arange(c.numel()) // fanout) for c in child_lists]
    nodes = InteriorNodes(
        means=cat(0, g.means.new_zeros(0, 3)), covars=cat(1, g.means.new_zeros(0, 3, 3)),
        opacities=cat(2, g.means.new_zeros(0)), sh=cat(3, g.means.new_zeros(0, K, 3)),
        radius=torch.cat(radius),
        child_ptr=torch.cat([torch.zeros(1, dtype=torch.long), torch.cumsum(torch.cat(counts), 0)]) if counts
        else torch.zeros(1, dtype=torch.long),
        child_ids=torch.cat(child_lists) if child_lists else torch.zeros(0, dtype=torch.long))
    return GaussianHierarchy(gaussians, nodes, target_px)


# ---- the cache beside the splat ---------------------------------------------------------------------

def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 24), b""):
            h.update(block)
    return h.hexdigest()


def save_nodes(path: Path, nodes: InteriorNodes, *, source_sha256: str, fanout: int) -> None:
    """Write `nodes` as an uncompressed npz, atomically, with the splat's hash and the build settings."""
    from wanderland_nav.atomic import atomic_path

    arrays = {f.name: getattr(nodes, f.name).cpu().numpy() for f in fields(nodes)}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays, source_sha256=np.array(source_sha256), fanout=np.array(fanout),
                     format_version=np.array(FORMAT_VERSION))


def load_nodes(path: Path, *, source_sha256: str, fanout: int) -> InteriorNodes | None:
    """The cached nodes when `path` holds a hierarchy of this splat (same hash, fanout, format); else None."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if (str(z["source_sha256"]) != source_sha256 or int(z["fanout"]) != fanout
                    or int(z["format_version"]) != FORMAT_VERSION):
                return None
            return InteriorNodes(*(torch.from_numpy(np.array(z[f.name])) for f in fields(InteriorNodes)))
    except (OSError, KeyError, ValueError):
        return None
