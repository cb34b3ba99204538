"""Atomic, resumable checkpoints.

One file per save (`ckpt_<iteration>.pt`) plus `last.pt`, each written to a temporary file and renamed
into place (`wanderland_nav.atomic`), so killing the run at any moment leaves the previous checkpoint
intact. A checkpoint holds the policy's state dict (which includes its normalisation buffers), the
optimiser, step counters, RNG states and the resolved config, so `load + restore` resumes where the run
stopped.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError, torch_load

CHECKPOINT_VERSION = 1


def rng_state() -> dict[str, Any]:
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])


def save_checkpoint(path: str | Path, *, policy: torch.nn.Module, optimizer: torch.optim.Optimizer | None,
                    counters: dict[str, int], config: dict | None = None, phase: str = "",
                    extra: dict | None = None) -> Path:
    """Write a checkpoint atomically to `path` and return it."""
    path = Path(path)
    payload = {
        "version": CHECKPOINT_VERSION,
        "phase": phase,
        "policy": policy.state_dict(),
        "optimizer": optimizer.state_dict() if optimizer is not None else None,
        "counters": dict(counters),
        "config": config,
        "rng": rng_state(),
        "extra": extra or {},
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint; missing -> FileNotFoundError, truncated/corrupt/foreign -> WanderlandInputError."""
    path = Path(path)
    # weights_only=False: the payload holds numpy RNG state and the config dict; checkpoints are our own
    ckpt = torch_load(path, what="checkpoint", weights_only=False)
    if not isinstance(ckpt, dict) or "policy" not in ckpt:
        raise WanderlandInputError("not a wanderland_nav checkpoint (no 'policy' field)", path=path)
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise WanderlandInputError(f"checkpoint version {ckpt.get('version')} != {CHECKPOINT_VERSION}",
                                   path=path, field="version")
    return ckpt


def load_policy_weights(policy: torch.nn.Module, path: str | Path) -> dict[str, Any]:
    """Load only the policy weights (warm start from a BC checkpoint); strict, with a clear error."""
    ckpt = load_checkpoint(path)
    try:
        policy.load_state_dict(ckpt["policy"], strict=True)
    except RuntimeError as e:  # missing/unexpected keys or shape mismatches
        first = str(e).strip().splitlines()[1:3]
        raise ValueError(f"{path}: checkpoint does not fit {type(policy).__name__} (wrong policy or config?): "
                         f"{' '.join(s.strip() for s in first)}") from None
    return ckpt


class Checkpointer:
    """Saves `last.pt` (+ `ckpt_<it>.pt` every `keep_every`) in `directory` and finds the resume point."""

    def __init__(self, directory: str | Path, keep_every: int = 0):
        self.dir = Path(directory)
        self.keep_every = keep_every

    @property
    def last(self) -> Path:
        return self.dir / "last.pt"

    def save(self, iteration: int, **kwargs) -> Path:
        p = save_checkpoint(self.last, **kwargs)
        if self.keep_every and iteration % self.keep_every == 0:
            save_checkpoint(self.dir / f"ckpt_{iteration:06d}.pt", **kwargs)
        return p

    def resume(self) -> dict[str, Any] | None:
        return load_checkpoint(self.last) if self.last.is_file() else None
