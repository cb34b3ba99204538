"""Run small batched queries on one intra-op thread.

Why: every query in `planners/` (and the env's step around it) is a chain of small tensor ops on
`[B]`-sized arrays. With torch's OpenMP pool at 2+ threads, such ops still pay a fork/join, and on a
machine where other processes hold the cores the join waits for the pool's second thread to be
scheduled again: milliseconds per op instead of microseconds. Measured on the shared 2-core box
(load average ~10): `torch.cos` of 256 floats 1.4 us median with 1 thread, means of 0.3-11 ms with
2; the camera-off env step spent 60 % of its time in such waits. Switching the pool size costs ~3 us.
"""

from __future__ import annotations

import contextlib
from typing import Iterator

import torch


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Set torch's intra-op threads to 1 for the block, then restore the caller's setting."""
    with intra_op_threads(1):
        yield


@contextlib.contextmanager
def intra_op_threads(n: int) -> Iterator[None]:
    """Set torch's intra-op threads to `n` for the block, then restore the caller's setting."""
    before = torch.get_num_threads()
    if n == before:
        yield
        return
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
