"""Each distinct camera image encoded once: content keys for uint8 images, and a memo of their features.

Why: a policy reads the newest `context` frames of the env's RGB history, so consecutive steps of one agent
share `context - 1` images, and a PPO batch `[B, T]` holds each rendered image up to `context` times (and its
`next` view once more). Grouping images by content, not by position in the batch, removes that repetition
without assuming the batch's layout (an episode reset repeats its first frame; a minibatch is a random
subset), and it is exact: two images share a feature row only when their bytes are equal, which is checked,
never assumed from the hash.

Two levels:
* `distinct` inside one encoder call: the encoder runs on the distinct images and the rows are gathered back;
  gradients flow as before (the gather's backward sums the copies' gradients);
* `FrameMemo` across calls: the features of every distinct image of a batch, computed once without gradients
  and looked up by content; `NavPolicy.frame_features` uses it only for an encoder that takes no gradient
  (frozen, or under `no_grad`), so a loss computed through it has the same value and the same gradients.
"""

from __future__ import annotations

from typing import Callable

import torch

_COEFFS: dict[tuple[int, str], torch.Tensor] = {}


def _coeffs(width: int, device: torch.device) -> torch.Tensor:
    """`[width]` fixed random odd int64 multipliers (seeded: the same keys in every process)."""
    k = (width, str(device))
    if k not in _COEFFS:
        g = torch.Generator().manual_seed(0x5EED)
        _COEFFS[k] = (torch.randint(-(2 ** 62), 2 ** 62, (width,), generator=g, dtype=torch.long) | 1).to(device)
    return _COEFFS[k]


def content_keys(flat: torch.Tensor) -> torch.Tensor:
    """uint8 `[M, P]` images (one row each) -> int64 `[M]` keys, a multiply-add hash of the bytes taken four at
    a time (wrapping int64 arithmetic). Equal images get equal keys; unequal ones almost surely differ, and
    every user compares the bytes before trusting a match."""
    if flat.dtype != torch.uint8 or flat.dim() != 2:
        raise ValueError(f"content_keys: expected uint8 [M, P] images, got {flat.dtype} {tuple(flat.shape)}")
    words = flat.contiguous().view(torch.int32) if flat.shape[1] % 4 == 0 else flat
    return (words.long() * _coeffs(words.shape[1], flat.device)).sum(dim=1)


def distinct(flat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """uint8 `[M, P]` -> (`rep` `[U]` the first row of each distinct image, `inverse` `[M]` its slot), so that
    `flat[rep][inverse] == flat`. A key shared by unequal images (a hash collision) is not trusted: every row
    is then its own slot."""
    m = flat.shape[0]
    rows = torch.arange(m, device=flat.device)
    if m == 0:
        return rows, rows
    _, inverse = torch.unique(content_keys(flat), return_inverse=True)
    rep = torch.full((int(inverse.max()) + 1,), m, dtype=torch.long, device=flat.device)
    rep.scatter_reduce_(0, inverse, rows, reduce="amin")
    if not torch.equal(flat[rep][inverse], flat):
        return rows, rows
    return rep, inverse


class FrameMemo:
    """Features of a fixed set of images `[M, H, W, 3]`, per encoder, computed on first use without gradients
    and looked up by content. Images it does not hold are encoded on the spot (their distinct ones only)."""

    def __init__(self, frames: torch.Tensor, chunk: int = 1024):
        flat = frames.reshape(frames.shape[0], -1)
        rep, _ = distinct(flat)
        self.frames = frames[rep]                          # [U, H, W, 3] distinct images
        keys = content_keys(self.frames.reshape(len(rep), -1))
        self.keys, order = torch.sort(keys)                # sorted for searchsorted
        self.frames = self.frames[order]
        self.chunk = int(chunk)
        self._features: dict[int, torch.Tensor] = {}       # id(encoder) -> [U, D], rows as self.keys

    def __len__(self) -> int:
        return self.frames.shape[0]

    def features(self, encoder: torch.nn.Module, frames: torch.Tensor,
                 encode: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
        """uint8 `[M, H, W, 3]` -> `[M, D]`: held images from the memo, the others through `encode` (which
        must be the same map from images to features: the policy's preprocessing + `encoder`)."""
        table = self._features.get(id(encoder))
        if table is None:
            with torch.no_grad():
                table = torch.cat([encode(self.frames[i:i + self.chunk]) for i in range(0, len(self), self.chunk)])
            self._features[id(encoder)] = table
        flat = frames.reshape(frames.shape[0], -1)
        keys = content_keys(flat)
        pos = torch.searchsorted(self.keys, keys).clamp_max(len(self) - 1)
        hit = (self.keys[pos] == keys) & (self.frames[pos].reshape(len(pos), -1) == flat).all(dim=1)
        if bool(hit.all()):
            return table[pos]
        out = table[pos].clone()
        miss = (~hit).nonzero().squeeze(1)
        rep, inverse = distinct(flat[miss])
        out[miss] = encode(frames[miss][rep])[inverse].to(out.dtype)
        return out
