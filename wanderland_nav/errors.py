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
from pathlib import Path
from typing import Any


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


def torch_load(path: str | os.PathLike, *, what: str, weights_only: bool, map_location: Any = "cpu") -> Any:
    """`torch.load` that names the file: missing -> FileNotFoundError, truncated/corrupt -> WanderlandInputError.

    torch's own messages ("PytorchStreamReader failed reading zip archive", "invalid load key") name
    no file, and a run that reads several checkpoints cannot say which one is broken.
    """
    import pickle
    import zipfile

    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    try:
        return torch.load(path, map_location=map_location, weights_only=weights_only)
    except (RuntimeError, EOFError, pickle.UnpicklingError, zipfile.BadZipFile, ValueError, OSError) as e:
        detail = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise WanderlandInputError(f"not a readable {what} (truncated or corrupt; delete it to start "
                                   f"fresh): {detail}", path=path) from e
