"""Run independent renderer calls on K Python threads, each with ONE intra-op thread.

Why: at the simulator's operating points (B = 64 cameras, 32x32 or 64x64 px) a render is thousands
of small tensor ops. Torch's OpenMP pool at 2 threads pays a fork/join barrier per op and gave only
1.24x of 1 thread (idle 2-core box: 338.9 vs 274.0 agent-frames/s). Torch ops release the GIL, so K
Python threads that each run whole renderer calls on one intra-op thread keep K cores busy with no
barrier inside a call (`experiments/env/README.md` has the figures).

Determinism: the caller splits the work into items that never depend on K (the env: fixed groups of
`render_chunk` cameras) and each item is computed by the same single-threaded code whichever
thread runs it, so results are bit-identical for any K. Workers pull items from a shared queue,
which balances groups of unequal cost (per-camera cost varies ~2x between views).

OpenMP's thread count is a per-thread setting, but torch also keeps a process default that a
worker's `torch.set_num_threads(1)` changes, and under pytest the caller's count was seen to follow
it: the caller reads its count before any helper starts and sets it back when all have finished.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Sequence, TypeVar

import torch

T = TypeVar("T")
R = TypeVar("R")

_pools: dict[int, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()


def _forget_pools_in_child() -> None:
    """A forked child (multiprocessing collectors) inherits the pools but not their threads: work sent
    there would wait forever. It starts its own pools on first use instead."""
    global _pools_lock
    _pools.clear()
    _pools_lock = threading.Lock()


os.register_at_fork(after_in_child=_forget_pools_in_child)


def _one_intra_op_thread() -> None:
    torch.set_num_threads(1)


def _pool(helpers: int) -> ThreadPoolExecutor:
    """A process-wide pool of `helpers` daemon threads (the caller is the K-th worker)."""
    with _pools_lock:
        if helpers not in _pools:
            _pools[helpers] = ThreadPoolExecutor(helpers, thread_name_prefix="render-shard",
                                                 initializer=_one_intra_op_thread)
        return _pools[helpers]


def map_single_threaded(fn: Callable[[T], R], items: Sequence[T], workers: int) -> list[R]:
    """`[fn(x) for x in items]`, computed by `min(workers, len(items))` threads (the caller included),
    each running its torch ops on ONE intra-op thread, the caller too (a lone small render on 2 OpenMP
    threads only pays barriers). Grad mode follows the caller's (it is thread-local in torch). The
    first exception raised by any `fn(x)` is re-raised once all threads have stopped."""
    workers = max(1, min(int(workers), len(items)))
    results: list = [None] * len(items)
    errors: list[BaseException] = []
    order = iter(range(len(items)))
    lock = threading.Lock()
    grad = torch.is_grad_enabled()

    def drain() -> None:
        if torch.get_num_threads() != 1:  # helpers: set at start, but re-checked (see the module docstring)
            torch.set_num_threads(1)
        with torch.set_grad_enabled(grad):
            while not errors:
                with lock:
                    i = next(order, None)
                if i is None:
                    return
                try:
                    results[i] = fn(items[i])
                except BaseException as e:  # noqa: BLE001  re-raised in the caller below
                    errors.append(e)

    n = torch.get_num_threads()  # before the helpers start (see the module docstring)
    futures = [_pool(workers - 1).submit(drain) for _ in range(workers - 1)] if workers > 1 else []
    torch.set_num_threads(1)
    try:
        drain()
    finally:
        for f in futures:
            f.result()
        torch.set_num_threads(n)  # also resets the process default that the workers' setting changed
    if errors:
        raise errors[0]
    return results
