"""`render.shards.map_single_threaded`: K Python threads, one intra-op thread each, results in order."""

from __future__ import annotations

import threading

import pytest
import torch

from wanderland_nav.render.shards import map_single_threaded


def test_results_in_order_on_several_threads_with_one_intra_op_thread_each():
    torch.set_num_threads(2)
    barrier = threading.Barrier(2, timeout=10)  # both workers must hold an item at the same time

    def probe(i):
        if i < 2:
            barrier.wait()
        return i, threading.get_ident(), torch.get_num_threads(), torch.is_grad_enabled()

    with torch.no_grad():
        out = map_single_threaded(probe, list(range(6)), workers=2)
    assert [o[0] for o in out] == list(range(6))
    assert len({o[1] for o in out}) == 2  # the caller and one helper
    assert all(o[2] == 1 for o in out)  # one intra-op thread in every worker, the caller included
    assert not any(o[3] for o in out)  # grad mode is thread-local: the caller's no_grad reaches the helpers
    assert torch.get_num_threads() == 2  # the caller's setting restored
    again = map_single_threaded(probe, list(range(2, 6)), workers=2)  # the pool's threads are reused
    assert all(o[2] == 1 for o in again) and torch.get_num_threads() == 2


def test_single_worker_runs_in_the_caller_on_one_thread():
    torch.set_num_threads(2)
    caller = threading.get_ident()
    out = map_single_threaded(lambda i: (threading.get_ident(), torch.get_num_threads()), [0, 1], workers=1)
    assert out == [(caller, 1), (caller, 1)] and torch.get_num_threads() == 2


def test_an_exception_in_a_worker_reaches_the_caller():
    def fail_on_three(i):
        if i == 3:
            raise ValueError("item 3 is bad")
        return i

    torch.set_num_threads(2)
    with pytest.raises(ValueError, match="item 3 is bad"):
        map_single_threaded(fail_on_three, list(range(8)), workers=2)
    assert torch.get_num_threads() == 2


def test_a_forked_child_gets_its_own_threads():
    """Multiprocessing collectors fork: the pool's threads do not exist in the child, work must not hang there."""
    import multiprocessing as mp

    torch.set_num_threads(2)
    map_single_threaded(lambda i: i, [0, 1], workers=2)  # the parent's pool exists now
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        out = pool.apply_async(_square_on_two_threads).get(timeout=60)
    assert out == [0, 1, 4, 9]


def _square_on_two_threads():
    torch.set_num_threads(2)
    return map_single_threaded(lambda i: i * i, list(range(4)), workers=2)
