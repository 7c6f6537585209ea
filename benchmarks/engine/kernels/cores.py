"""Every run of a batch on every core: the runs split into one contiguous
share per thread, each share advanced by a kernel's compiled loop
(``advance_runs(first, last, …)``, serial, releasing the GIL) in a thread
of its own, the last share in the caller's.

Why threads and not numba's parallel loop (``prange``): the arithmetic of
each run is the same, in the same order, so every number is the same to
the bit, and numba's parallel passes, which lower a ``prange`` loop, took
about half of a kernel's compile (measured on a cold cache: the MEKF's
kernel 89 s with ``parallel=True``, 47 s without). Runs never interact, so
the shares need no lock. The threads are numba's count
(:func:`numba.get_num_threads`, which a campaign's worker sets), as the
parallel loop's were.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool() -> ThreadPoolExecutor:
    """The threads that run every share but the caller's, made once per
    process (a forked child, which inherits the pool but not its threads,
    makes its own)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            from numba import config
            _POOL = ThreadPoolExecutor(max_workers=max(1, config.NUMBA_NUM_THREADS - 1),
                                       thread_name_prefix="kernel")
        return _POOL


def _forget_pool() -> None:
    global _POOL, _POOL_LOCK
    _POOL, _POOL_LOCK = None, threading.Lock()


os.register_at_fork(after_in_child=_forget_pool)


def on_every_core(advance_runs, n_runs: int, *args, threads: int | None = None) -> None:
    """``advance_runs(first, last, *args)`` over runs ``0 … n_runs - 1``,
    one contiguous share per thread (``threads``, default numba's count).
    Every share has finished when it returns, whatever raised (the first
    error is raised then)."""
    from numba import get_num_threads
    threads = max(1, min(get_num_threads() if threads is None else threads, n_runs))
    bounds = np.linspace(0, n_runs, threads + 1).round().astype(np.int64)
    shares = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
    futures = [_pool().submit(advance_runs, first, last, *args) for first, last in shares[:-1]]
    try:
        advance_runs(*shares[-1], *args)
    finally:
        wait(futures)
    for future in futures:
        future.result()


def on_every_core_of(advance_runs):
    """A kernel's ``advance(block, sensors, state, record, row)``: every run
    of the batch (the record's, :class:`~benchmarks.engine.kernels.common.Record`)
    through the block by ``advance_runs``, one share per core."""
    def advance(block, sensors, state, record, row):
        on_every_core(advance_runs, record.diverged.shape[1], block, sensors, state, record,
                      row)
    advance.__doc__ = (f"Every run through ``block``: ``{advance_runs.__name__}`` of "
                       f"{advance_runs.__module__} on every core.")
    return advance
