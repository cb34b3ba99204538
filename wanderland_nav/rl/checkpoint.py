"""Atomic, resumable checkpoints.

One file per save (`ckpt_<iteration>.pt`) plus `last.pt`, each written to a temporary file and renamed
into place (`wanderland_nav.atomic`), so killing the run at any moment leaves the previous checkpoint
intact. A checkpoint holds the policy's state dict (which includes its normalisation buffers), the
optimiser, step counters, RNG states and the resolved config, so `load + restore` resumes where the run
stopped, and the policy card (`card`: the policy's config and what it needs from the env, `compose.checkpoints`),
so any consumer rebuilds the policy without the training config.

Loading never runs code from the file: every load is `torch.load(weights_only=True)`, so the payload is
plain data only (tensors, numbers, strings, lists, dicts; the numpy RNG state is stored as a tensor), and
a file that needs anything else (a pickled class, `os.system` in a crafted file) is refused with its name
and the global it asked for. Checkpoints are shared between people; a `.pt` is a pickle.
"""

from __future__ import annotations

import random
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError, torch_load

CHECKPOINT_VERSION = 1


def rng_state() -> dict[str, Any]:
    """Every RNG's state as plain data (numpy's MT19937 key as an int64 tensor, not an ndarray)."""
    npst = np.random.get_state(legacy=False)
    npst["state"] = {"key": torch.from_numpy(npst["state"]["key"].astype(np.int64)), "pos": int(npst["state"]["pos"])}
    return {"torch": torch.get_rng_state(), "numpy": npst, "python": random.getstate()}


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    npst = state["numpy"]
    if isinstance(npst, dict):  # rng_state()'s form; a tuple is numpy's legacy form (older checkpoints)
        inner = npst["state"]
        npst = {**npst, "state": {"key": np.asarray(inner["key"], dtype=np.uint32), "pos": int(inner["pos"])}}
    np.random.set_state(npst)
    random.setstate(state["python"])


# what a checkpoint written before the RNG state became plain data needs: numeric ndarrays, nothing callable
_LEGACY_NUMPY = (np._core.multiarray._reconstruct, np.ndarray, np.dtype, np.dtypes.UInt32DType)


def _plain_data(value: Any, where: str = "checkpoint") -> Any:
    """`value` as what `weights_only=True` loads back: numpy scalars become Python numbers (lossless); anything
    else that is not plain data is refused naming its key, so a save never writes what a safe load refuses.
    Containers come back as they are (state dicts keep their `_metadata`) unless a value in them changed."""
    if isinstance(value, np.generic) and value.dtype.kind in "biuf":
        return value.item()
    if value is None or type(value) in (bool, int, float, str) or isinstance(value, (torch.Tensor, torch.Size)):
        return value
    if type(value) in (dict, OrderedDict):
        bad = next((k for k in value if type(k) not in (str, int)), None)
        if bad is not None:
            raise TypeError(f"{where}: key {bad!r} is a {type(bad).__name__}, not plain data")
        new = {k: _plain_data(v, f"{where}.{k}") for k, v in value.items()}
        return value if all(new[k] is v for k, v in value.items()) else type(value)(new)
    if type(value) in (list, tuple):
        new = [_plain_data(v, f"{where}[{i}]") for i, v in enumerate(value)]
        return value if all(a is b for a, b in zip(new, value)) else type(value)(new)
    raise TypeError(f"{where} is a {type(value).__name__}: a checkpoint holds plain data only "
                    "(tensors, numbers, strings, lists, dicts), so it loads without running code")


def save_checkpoint(path: str | Path, *, policy: torch.nn.Module, optimizer: torch.optim.Optimizer | None,
                    counters: dict[str, int], config: dict | None = None, phase: str = "",
                    extra: dict | None = None, card: dict | None = None) -> Path:
    """Write a checkpoint atomically to `path` and return it."""
    path = Path(path)
    payload = {
        "version": CHECKPOINT_VERSION,
        "phase": phase,
        "policy": policy.state_dict(),
        "optimizer": optimizer.state_dict() if optimizer is not None else None,
        "counters": dict(counters),
        "config": config,
        "card": card,
        "rng": rng_state(),
        "extra": extra or {},
    }
    payload = _plain_data(payload)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint; missing -> FileNotFoundError, truncated/corrupt/foreign -> WanderlandInputError."""
    path = Path(path)
    with torch.serialization.safe_globals(list(_LEGACY_NUMPY)):
        ckpt = torch_load(path, what="checkpoint")
    if not isinstance(ckpt, dict) or "policy" not in ckpt:
        raise WanderlandInputError("not a wanderland_nav checkpoint (no 'policy' field)", path=path)
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise WanderlandInputError(f"checkpoint version {ckpt.get('version')} != {CHECKPOINT_VERSION}",
                                   path=path, field="version")
    return ckpt


def load_policy_weights(policy: torch.nn.Module, path: str | Path) -> dict[str, Any]:
    """Load only the policy weights (warm start from a BC checkpoint); strict, with a clear error."""
    ckpt = load_checkpoint(path)
    fit_policy_weights(policy, ckpt["policy"], path)
    return ckpt


def fit_policy_weights(policy: torch.nn.Module, state: dict, path: str | Path) -> None:
    """`policy.load_state_dict(state)`, refused first (`WanderlandInputError` naming `path` and the first weight
    missing, unexpected or of another shape) when the weights do not fit the policy its config builds."""
    own = policy.state_dict()
    where = f"checkpoint does not fit {type(policy).__name__} (another policy, or its config edited?)"
    for key, value in own.items():
        theirs = state.get(key) if isinstance(state, dict) else None
        if theirs is None:
            raise WanderlandInputError(f"{where}: weight {key!r} {list(value.shape)} is not in the file",
                                       path=path, field=f"policy.{key}")
        if tuple(getattr(theirs, "shape", ())) != tuple(value.shape):
            raise WanderlandInputError(f"{where}: weight {key!r} is {list(getattr(theirs, 'shape', ()))} in the file, "
                                       f"{list(value.shape)} in the policy", path=path, field=f"policy.{key}")
    extra = [k for k in state if k not in own]
    if extra:
        raise WanderlandInputError(f"{where}: the file has weight {extra[0]!r} the policy does not "
                                   f"({len(extra)} such)", path=path, field=f"policy.{extra[0]}")
    policy.load_state_dict(state, strict=True)


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
