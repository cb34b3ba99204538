"""Arrays on the wire: a dict of numpy arrays as one uncompressed `.npz` body (images stay uint8).

`.npz` because numpy reads and writes it with no extra dependency in any Python environment a model lives in,
it keeps dtype and shape, and `allow_pickle=False` makes reading it safe.

Reading is bounded before anything is decompressed or allocated: at most `MAX_MEMBERS` arrays, the sizes the
zip's members declare summing to at most `max_bytes`, and each array's own header (dtype and shape) declaring
no more bytes than its member holds. A zip bomb (a few kilobytes of deflated zeros declaring a gigabyte) or a
header claiming a huge shape is refused by those figures alone, since numpy would allocate the declared shape
before reading a byte of it.
"""

from __future__ import annotations

import io
import math
import zipfile
from typing import Collection, Mapping

import numpy as np

CONTENT_TYPE = "application/x-npz"
MAX_MEMBERS = 64  # arrays in one body: the protocol's observation keys are fewer than ten


def pack(arrays: Mapping[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return buf.getvalue()


def _declared(zf: zipfile.ZipFile, info: zipfile.ZipInfo, where: str) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype a member's `.npy` header declares, checked against the bytes the member holds."""
    try:
        with zf.open(info) as f:
            version = np.lib.format.read_magic(f)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                np.lib.format.read_array_header_2_0
            shape, _, dtype = read_header(f, max_header_size=10_000)
            header = f.tell()
    except ValueError as e:
        raise ValueError(f"{where}: member {info.filename!r} is not a .npy array ({e})") from None
    if dtype.hasobject:
        raise ValueError(f"{where}: array {info.filename!r} has dtype {dtype} (objects are not read)")
    need = math.prod(shape) * dtype.itemsize
    if need > info.file_size - header:
        raise ValueError(f"{where}: array {info.filename!r} declares shape {list(shape)} {dtype} ({need} bytes) but "
                         f"holds {info.file_size - header} bytes")
    return shape, dtype


def unpack(data: bytes, where: str, *, max_bytes: int | None = None,
           keys: Collection[str] | None = None) -> dict[str, np.ndarray]:
    """`.npz` bytes -> arrays; anything else raises `ValueError` naming `where`. `max_bytes`: the most the arrays
    may hold uncompressed (checked on the declared sizes, before reading); `keys`: the only names accepted."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            infos = zf.infolist()
            if len(infos) > MAX_MEMBERS:
                raise ValueError(f"{where}: {len(infos)} arrays, more than {MAX_MEMBERS}")
            total = sum(i.file_size for i in infos)
            if max_bytes is not None and total > max_bytes:
                raise ValueError(f"{where}: its arrays declare {total} bytes uncompressed ({len(data)} sent), above "
                                 f"the limit of {max_bytes} bytes")
            names = [i.filename.removesuffix(".npy") for i in infos]
            if keys is not None and set(names) - set(keys):
                raise ValueError(f"{where}: unexpected arrays {sorted(set(names) - set(keys))}; expected some of "
                                 f"{sorted(keys)}")
            for info in infos:
                _declared(zf, info, where)
    except (OSError, zipfile.BadZipFile, EOFError) as e:
        raise ValueError(f"{where}: not a .npz array bundle ({len(data)} bytes: {e})") from None
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as e:
        raise ValueError(f"{where}: not a .npz array bundle ({len(data)} bytes: {e})") from None
