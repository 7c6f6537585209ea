"""The kernels' borrowed arrays (benchmarks/engine/kernels/borrowed.py): the
same data, shape and strides as the array they borrow, read and written
through, alone, in tuples and named tuples, and through views of them."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays
from numba import njit, prange

from benchmarks.engine.kernels.borrowed import borrowed


class Pair(NamedTuple):
    values: np.ndarray
    scale: float


@njit(cache=False)
def _scaled_rows(a, factor):
    """Each row of ``a`` times ``factor``, written through borrowed row views."""
    b = borrowed(a)
    for i in range(b.shape[0]):
        row = b[i]
        for j in range(row.shape[0]):
            row[j] *= factor


@njit(cache=False)
def _sum_strided(a):
    """The sum of every second column of ``a`` read through a borrowed view."""
    view = borrowed(a)[:, ::2]
    total = 0.0
    for i in range(view.shape[0]):
        for j in range(view.shape[1]):
            total += view[i, j]
    return total


@njit(cache=False)
def _through_tuples(pair, extra):
    """A named tuple and a plain one, borrowed whole: arrays written, scalars kept."""
    inner, (other, count) = borrowed((pair, extra))
    for i in range(inner.values.shape[0]):
        inner.values[i] = inner.values[i] * inner.scale + count
        other[i] = -inner.values[i]
    return inner.scale, count


@njit(parallel=True, cache=False)
def _parallel_rows(a):
    """Each run's row written in a parallel loop, as a kernel writes its state."""
    rows = borrowed(a)
    for index in prange(rows.shape[0]):
        run = np.int64(index)
        row = rows[run]
        for j in range(row.shape[0]):
            row[j] = run * 10.0 + j


@settings(max_examples=30, deadline=None)
@given(arrays(np.float64, array_shapes(min_dims=2, max_dims=2, max_side=6),
              elements=st.floats(-1e6, 1e6)),
       st.floats(-4.0, 4.0))
def test_writes_through_borrowed_views_reach_the_array(a, factor):
    expected = a * factor
    _scaled_rows(a, factor)
    np.testing.assert_array_equal(a, expected)


@settings(max_examples=30, deadline=None)
@given(arrays(np.float64, array_shapes(min_dims=2, max_dims=2, max_side=7),
              elements=st.floats(-1e3, 1e3)))
def test_a_borrowed_strided_view_reads_the_array(a):
    # Summed in the same order as the loop: the same float to the bit.
    expected = 0.0
    for value in a[:, ::2].ravel():
        expected += value
    assert _sum_strided(a) == expected


def test_tuples_keep_their_scalars_and_share_their_arrays():
    values, other = np.array([1.0, 2.0, 3.0]), np.zeros(3)
    assert _through_tuples(Pair(values, 2.0), (other, 5)) == (2.0, 5)
    np.testing.assert_array_equal(values, [7.0, 9.0, 11.0])
    np.testing.assert_array_equal(other, [-7.0, -9.0, -11.0])


def test_each_run_of_a_parallel_loop_writes_its_own_row():
    a = np.zeros((64, 3))
    _parallel_rows(a)
    np.testing.assert_array_equal(a, np.arange(64)[:, None] * 10.0 + np.arange(3))
