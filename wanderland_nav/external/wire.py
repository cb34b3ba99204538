"""Arrays on the wire: a dict of numpy arrays as one uncompressed `.npz` body (images stay uint8).

`.npz` because numpy reads and writes it with no extra dependency in any Python environment a model lives in,
it keeps dtype and shape, and `allow_pickle=False` makes reading it safe.
"""

from __future__ import annotations

import io
import zipfile
from typing import Mapping

import numpy as np

CONTENT_TYPE = "application/x-npz"


def pack(arrays: Mapping[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return buf.getvalue()


def unpack(data: bytes, where: str) -> dict[str, np.ndarray]:
    """`.npz` bytes -> arrays; anything else raises `ValueError` naming `where`."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as e:
        raise ValueError(f"{where}: not a .npz array bundle ({len(data)} bytes: {e})") from None
