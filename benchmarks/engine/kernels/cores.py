"""Every run of a batch on every core: the runs split into contiguous
shares, each advanced by a kernel's compiled loop (``advance_runs(first,
last, …)``, serial, releasing the GIL), taken in turn by every thread (the
caller's too) until none is left.

Why several shares a thread, taken as each thread comes free: a core that
is also doing other work (a CubeSat campaign's vector readings are made
beside the kernels; another process) would otherwise hold every other
thread waiting for its one share at the end of each block (the README's
performance section has the CubeSat's times before and after).

Why threads and not numba's parallel loop (``prange``): the arithmetic of
each run is the same, in the same order, so every number is the same to
the bit, and numba's parallel passes, which lower a ``prange`` loop, took
about half of a kernel's compile (measured on a cold cache: the MEKF's
kernel 89 s with ``parallel=True``, 47 s without). Runs never interact, so
the shares need no lock (only the count of shares taken has one). The
threads are numba's count (:func:`numba.get_num_threads`, which a
campaign's worker sets), as the parallel loop's were.
"""
from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

#: Shares a thread, at most (fewer where a share would have under
#: :data:`MIN_SHARE_RUNS` runs): enough for the threads to even out a core
#: that is busy elsewhere, few enough that a share's call costs nothing.
SHARES_PER_THREAD = 8
MIN_SHARE_RUNS = 16

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
    """``advance_runs(first, last, *args)`` over runs ``0 … n_runs - 1``, in
    contiguous shares taken in turn by each thread (``threads``, default
    numba's count). Every share taken has finished when it returns; after
    an error no further share is taken, and the first error is raised."""
    from numba import get_num_threads
    threads = max(1, min(get_num_threads() if threads is None else threads, n_runs))
    bounds = share_bounds(n_runs, threads)
    counter, lock, failed = itertools.count(), threading.Lock(), threading.Event()

    def next_share():
        with lock:
            return next(counter)

    def take_shares():
        try:
            for share in iter(next_share, None):
                if share >= len(bounds) - 1 or failed.is_set():
                    return
                advance_runs(bounds[share], bounds[share + 1], *args)
        except BaseException:       # an interrupt between two shares too
            failed.set()
            raise

    futures = [_pool().submit(take_shares) for _ in range(threads - 1)]
    try:
        take_shares()
    finally:
        wait(futures)
    for future in futures:
        future.result()


def share_bounds(n_runs: int, threads: int) -> list:
    """The shares' bounds: ``[0, …, n_runs]``, :data:`SHARES_PER_THREAD` a
    thread of at least :data:`MIN_SHARE_RUNS` runs (one a thread at least,
    and no share empty: never more threads than runs)."""
    threads = max(1, min(threads, n_runs))
    shares = max(threads, min(threads * SHARES_PER_THREAD, n_runs // MIN_SHARE_RUNS))
    return np.linspace(0, n_runs, shares + 1).round().astype(np.int64).tolist()


def on_every_core_of(advance_runs):
    """A kernel's ``advance(block, sensors, state, record, row)``: every run
    of the batch (the record's, :class:`~benchmarks.engine.kernels.common.Record`)
    through the block by ``advance_runs``, on every core."""
    def advance(block, sensors, state, record, row):
        on_every_core(advance_runs, record.diverged.shape[1], block, sensors, state, record,
                      row)
    advance.__doc__ = (f"Every run through ``block``: ``{advance_runs.__name__}`` of "
                       f"{advance_runs.__module__} on every core.")
    return advance


def on_every_core_in_lanes(advance_runs, lanes):
    """A kernel's ``advance`` with a second form in lanes (module ``lanes``:
    its ``advance_lanes``, eight runs side by side, where its
    ``lanes_apply(block, record, state)`` says it covers the case, a
    campaign's; ``advance_runs``, one run at a time, otherwise): the same
    numbers either way, a share of the runs per core."""
    one_by_one = on_every_core_of(advance_runs)

    def advance(block, sensors, state, record, row):
        if not lanes.lanes_apply(block, record, state):
            one_by_one(block, sensors, state, record, row)
            return
        on_every_core(lanes.advance_lanes, record.diverged.shape[1], block, sensors, state,
                      record, row)
    advance.__doc__ = (f"Every run through ``block``: {lanes.__name__}.advance_lanes where it "
                       f"applies, else {advance_runs.__module__}.{advance_runs.__name__}.")
    return advance
