"""What the kernels in lanes share: eight runs advanced side by side, so that
the processor's vector units (four doubles at a time with AVX2) do the
arithmetic of several runs in one instruction.

Why: a one-run kernel's step is a few hundred scalar operations (the
propagation, its Jacobian, the covariance, the attitude error's arccos)
that the processor retires one by one. In lanes each quantity is a row of
:data:`LANES` numbers, one a run, in one buffer with its rows a constant
stride apart, and each part of a step is a loop over the lanes whose body
reads its rows into values, computes and writes them back, without calls
or branches: LLVM's loop vectorizer turns it into vector instructions.
(One buffer, so that it can prove the lanes apart; several arrays, rows a
run-time stride apart, a body storing and reloading many rows, or a
helper indexing a tuple with a loop variable left it scalar: measured.)

What is not the same arithmetic on every lane is done lane by lane with
the functions the one-run kernels call: the star tracker's readings
(:func:`star_readings`) and each kernel's update (due every few steps,
not in every lane at once; its Gauss–Jordan pivots on each lane's data:
the EKF's, written on values with choices instead of branches, ran no
faster and took 13 minutes to compile), the histogram's count (a
scatter), a divergence's bookkeeping and the rare error above 120° (the
library's arccos).

The same operations in the same order as the one-run kernels, so the same
numbers to the bit (no fast-math, no reassociation; tests/test_engine_lanes.py
holds each kernel in lanes to its one-run kernel at every step).

Every buffer begins with the rows here (the estimate's quaternion, the
gyro's reading, the error's and the statistics' rows); a kernel's own rows
follow from :data:`OWN_ROWS` (:func:`first_rows`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.engine.kernels.common import (HIGH_WORD_MASK, RAD_TO_DEG, acos_near_one,
                                              count_error, mark_diverged, welford)
from benchmarks.engine.kernels.sensors import star_step

#: Runs advanced side by side: two AVX2 vectors of four doubles each.
LANES = 8


def first_rows(start: int = 0, **sizes) -> tuple:
    """Each quantity's first row in a group's buffer, in order from row
    ``start``, then the rows in all."""
    return tuple(int(row) for row in np.cumsum((start,) + tuple(sizes.values())))


# The rows every buffer begins with, LANES numbers a row: the estimate's
# quaternion (the output the error is of), the gyro's reading; the |q̂ · q|
# of the error, the arccos's √z, its high word and its value, the error,
# the run's statistics (Record.stats' MEAN, M2, MAX, FINAL of common),
# whether it diverged (1.0) or its error needs a lane's own care (1.0), its
# divergence test (NaN: not finite).
(Q, W, _DOT, _ROOT, _HIGH, _ACOS, _ERROR, _STATS, _DIVERGED, _OWN, CHECK,
 OWN_ROWS) = first_rows(q=4, w=3, dot=1, root=1, high=1, acos=1, error=1, stats=4, diverged=1,
                        own=1, check=1)


def campaign_case(block, record) -> bool:
    """What every kernel in lanes needs of a block and record: a gyro with
    white noise only (no scale factor, no bias), and statistics only (no
    NEES, traces or health checks)."""
    return not (block.has_scale or block.has_bias or record.consistency or record.keep_traces
                or record.check_health)


@njit(cache=True, inline="always", error_model="numpy")
def three(b, row, lane):
    """Rows ``row`` to ``row + 2`` of one lane, as values."""
    return b[row * LANES + lane], b[(row + 1) * LANES + lane], b[(row + 2) * LANES + lane]


@njit(cache=True, inline="always", error_model="numpy")
def nine(b, row, lane):
    """Rows ``row`` to ``row + 8`` of one lane, as values (a 3x3, row-major)."""
    return three(b, row, lane) + three(b, row + 3, lane) + three(b, row + 6, lane)


@njit(cache=True, inline="always", error_model="numpy")
def put_two(b, row, lane, values):
    """Two values into one lane's rows ``row`` and ``row + 1``."""
    b[row * LANES + lane] = values[0]
    b[(row + 1) * LANES + lane] = values[1]


@njit(cache=True, inline="always", error_model="numpy")
def put_three(b, row, lane, values):
    """Three values into one lane's rows from ``row``."""
    put_two(b, row, lane, values[:2])
    b[(row + 2) * LANES + lane] = values[2]


@njit(cache=True, inline="always", error_model="numpy")
def gyro(b, m, t, first, omega, std, normals):
    """Each lane's gyro reading ω + σ N (sensors.gyro_reading's white-noise case)."""
    for i in range(3):
        for lane in range(m):
            run = first + lane
            b[(W + i) * LANES + lane] = omega[t, i] + std[run] * normals[run, t, i]


@njit(cache=True, inline="always", error_model="numpy")
def attitude_error(b, bits, m, q_true_k):
    """Each lane's |q̂ · q| and, for it, common.acos's fdlibm branch (x >= 1
    is 0 in :func:`fold`, x <= 0.5 the library's in :func:`fold_own`)."""
    for lane in range(m):
        dot = abs(q_true_k[0] * b[Q * LANES + lane] + q_true_k[1] * b[(Q + 1) * LANES + lane]
                  + q_true_k[2] * b[(Q + 2) * LANES + lane]
                  + q_true_k[3] * b[(Q + 3) * LANES + lane])
        b[_DOT * LANES + lane] = dot
        s = math.sqrt((1.0 - min(1.0, dot)) * 0.5)
        b[_ROOT * LANES + lane] = s
        b[_HIGH * LANES + lane] = s
    for lane in range(m):        # acos's bits_int & HIGH_WORD_MASK
        bits[_HIGH * LANES + lane] = bits[_HIGH * LANES + lane] & HIGH_WORD_MASK
    for lane in range(m):
        z = (1.0 - min(1.0, b[_DOT * LANES + lane])) * 0.5
        b[_ACOS * LANES + lane] = acos_near_one(z, b[_ROOT * LANES + lane],
                                                b[_HIGH * LANES + lane])


@njit(cache=True, inline="always", error_model="numpy")
def fold(b, m, k):
    """Each lane's error at step ``k`` folded into its statistics' rows
    (common.fold_error's Welford), where the error is the arccos's fdlibm
    branch and the run has not diverged; the other lanes are marked for
    :func:`fold_own` and left as they were."""
    inv_count = 1.0 / (k + 1)
    for lane in range(m):
        dot = b[_DOT * LANES + lane]
        x = min(1.0, dot)
        error = 2.0 * (0.0 if x >= 1.0 else b[_ACOS * LANES + lane]) * RAD_TO_DEG
        own = b[_DIVERGED * LANES + lane] != 0.0 or not dot < math.inf or x <= 0.5
        mean, m2, maximum = welford(b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane],
                                    b[(_STATS + 2) * LANES + lane], error, inv_count, k == 0)
        b[_STATS * LANES + lane] = b[_STATS * LANES + lane] if own else mean
        b[(_STATS + 1) * LANES + lane] = b[(_STATS + 1) * LANES + lane] if own else m2
        b[(_STATS + 2) * LANES + lane] = b[(_STATS + 2) * LANES + lane] if own else maximum
        b[(_STATS + 3) * LANES + lane] = b[(_STATS + 3) * LANES + lane] if own else error
        b[_ERROR * LANES + lane] = error
        b[_OWN * LANES + lane] = 1.0 if own else 0.0


@njit(cache=True, inline="always", error_model="numpy")
def fold_own(b, m, first, k, errors, words, words_int):
    """What :func:`fold` leaves to each lane: a divergence marked, an error
    at x <= 0.5 from the library's arccos (as common.acos takes it), then the
    histogram's count and the kept sample (common.count_error; ``words``,
    ``words_int``: its scratch float and int64 view)."""
    hist, first_bits, traces, keep_traces, every, samples, diverged = errors[1:8]
    for lane in range(m):
        run = np.int64(first + lane)
        if b[_OWN * LANES + lane] != 0.0:
            dot = b[_DOT * LANES + lane]
            if b[_DIVERGED * LANES + lane] != 0.0 or not math.isfinite(dot):
                mark_diverged(run, k, diverged, traces, keep_traces, every, samples)
                b[_DIVERGED * LANES + lane] = 1.0
                continue
            error = 2.0 * math.acos(min(1.0, dot)) * RAD_TO_DEG
            mean, m2, maximum = welford(b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane],
                                        b[(_STATS + 2) * LANES + lane], error, 1.0 / (k + 1),
                                        k == 0)
            b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane] = mean, m2
            b[(_STATS + 2) * LANES + lane], b[(_STATS + 3) * LANES + lane] = maximum, error
            b[_ERROR * LANES + lane] = error
        count_error(run, k, b[_ERROR * LANES + lane], hist, first_bits, every, samples, words,
                    words_int)


@njit(cache=True, inline="always", error_model="numpy")
def record_error(b, bits, m, first, k, q_true_k, errors, words, words_int):
    """Each lane's error of its estimate at step ``k`` folded into its run's
    statistics, histogram and samples (common.record_error, in lanes)."""
    attitude_error(b, bits, m, q_true_k)
    fold(b, m, k)
    fold_own(b, m, first, k, errors, words, words_int)


@njit(cache=True, inline="always", error_model="numpy")
def mark_failed(b, m, first, k, errors):
    """The lanes whose :data:`CHECK` row a kernel's divergence test left NaN
    (a sum times 0 that was not finite) marked diverged at step ``k``."""
    traces, keep_traces, every, samples, diverged = errors[3:8]
    for lane in range(m):
        if b[CHECK * LANES + lane] != b[CHECK * LANES + lane]:
            mark_diverged(np.int64(first + lane), k, diverged, traces, keep_traces, every,
                          samples)
            b[_DIVERGED * LANES + lane] = 1.0


@njit(cache=True, inline="always", error_model="numpy")
def star_readings(m, first, j, countdown, reading, q_true, star, z, dq, due):
    """Each lane's star tracker at the block's step ``j``: ``due[lane]``
    whether a reading is available, made into ``z[lane]`` (``dq``: scratch)."""
    for lane in range(m):
        if countdown[lane] > 0:        # star_step's first case, without its call
            countdown[lane] -= 1
            due[lane] = False
            continue
        due[lane], countdown[lane], reading[lane] = star_step(
            z[lane], dq, np.int64(first + lane), j, countdown[lane], reading[lane], q_true, star)


@njit(cache=True, inline="always", error_model="numpy")
def group_errors(b, m, first, q_all, stats, diverged, back):
    """The group's estimates, statistics and divergence into the buffer's
    rows, or (``back``) the estimates and statistics out of them."""
    for lane in range(m):
        run = first + lane
        for i in range(4):
            if back:
                q_all[run, i] = b[(Q + i) * LANES + lane]
                stats[run, i] = b[(_STATS + i) * LANES + lane]
            else:
                b[(Q + i) * LANES + lane] = q_all[run, i]
                b[(_STATS + i) * LANES + lane] = stats[run, i]
        if not back:
            b[_DIVERGED * LANES + lane] = 1.0 if diverged[run] >= 0 else 0.0


@njit(cache=True, inline="always", error_model="numpy")
def rows_to_array(b, row, lane, out):
    """Rows ``row`` onward of one lane into ``out`` (any shape, C order)."""
    flat = out.reshape(out.size)
    for i in range(out.size):
        flat[i] = b[(row + i) * LANES + lane]


@njit(cache=True, inline="always", error_model="numpy")
def array_to_rows(b, row, lane, values):
    """``values`` (any shape, C order) into one lane's rows ``row`` onward."""
    flat = values.reshape(values.size)
    for i in range(values.size):
        b[(row + i) * LANES + lane] = flat[i]
