"""The project's error type for bad input: every reader raises it naming the file and what is wrong.

`WanderlandInputError` is a `ValueError`, so `except ValueError` keeps working; the format-specific
errors (`SceneFormatError`, `ColmapFormatError`, `PointCloudFormatError`, `PlyError`,
`EpisodeFormatError`, `RolloutFormatError`) are subclasses, so one `except WanderlandInputError`
catches any unreadable input, and `.path` / `.field` say where to look without parsing the message.

`planners` may not import `wanderland_nav`; its own `planners.NavMeshFileError` (also a
`ValueError` carrying `.path`) plays the same role for `navmesh.npz`.
"""

from __future__ import annotations

import os
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any

import torch


class WanderlandInputError(ValueError):
    """An input file (or in-memory input) that cannot be used: missing, truncated, corrupt or inconsistent.

    `WanderlandInputError("truncated", path=p, field="vertex")` reads "p: field 'vertex': truncated";
    a message that already starts with the path is kept as it is (the older format errors do that).
    """

    def __init__(self, message: str, *, path: str | os.PathLike | None = None, field: str | None = None):
        text = str(message)
        if field is not None and f"'{field}'" not in text:
            text = f"field '{field}': {text}"
        if path is not None and not text.startswith(str(path)):
            text = f"{path}: {text}"
        super().__init__(text)
        self.path = Path(path) if path is not None else None
        self.field = field


class NonFiniteLossError(RuntimeError):
    """Training diverged: a loss term or gradient norm became NaN/inf. The message names where (iteration,
    epoch, minibatch or round/update) and which term; raised before the optimiser steps on it."""


def torch_load(path: str | os.PathLike, *, what: str, map_location: Any = "cpu") -> Any:
    """`torch.load(weights_only=True)` that names the file: missing -> FileNotFoundError, truncated/corrupt ->
    WanderlandInputError, and a file that asks for a global (a class, `os.system`) refused as such.

    torch's own messages ("PytorchStreamReader failed reading zip archive", "invalid load key") name
    no file, and a run that reads several checkpoints cannot say which one is broken. Never
    `weights_only=False`: a `.pt` is a pickle, and checkpoints are passed between people.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except (RuntimeError, EOFError, pickle.UnpicklingError, zipfile.BadZipFile, ValueError, OSError) as e:
        text = str(e)
        needs = re.search(r"unsupported (?:global: )?GLOBAL ([\w.]+)", text, re.I)
        if needs:  # weights_only=True met a pickled callable or class: the file wants to run code
            raise WanderlandInputError(
                f"{what} refused: it needs code to load (global {needs.group(1)}), and loading it could run "
                "that code; only plain-data files (tensors, numbers, strings, lists, dicts) are read",
                path=path) from None
        why = re.search(r"WeightsUnpickler error:\s*(\S[^\n]*)", text)  # torch's own line, under its boilerplate
        detail = why.group(1) if why else text.strip().splitlines()[0] if text.strip() else type(e).__name__
        raise WanderlandInputError(f"not a readable {what} (truncated or corrupt; delete it to start "
                                   f"fresh): {detail}", path=path) from e
