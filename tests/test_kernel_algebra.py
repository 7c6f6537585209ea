"""The engine's compiled algebra: shortcuts that must keep every bit.

The MEKF's Joseph update skips the products of I − KH's gyro-bias columns
when H is zero there (those columns are the identity's). Every campaign's
numbers stay bit for bit only if the shortcut gives the full product's bits
for every finite input, signed zeros included; a property test holds it so.
"""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from benchmarks.engine.kernels.algebra import joseph_covariance


def _joseph_inputs(seed: int, n: int, sparse: bool):
    """P, I − KH (H zero in the bias columns 3 to 5) and K R Kᵀ for ``n`` states;
    ``sparse``: a diagonal P and a K with exact zeros, where signed zeros arise."""
    rng = np.random.default_rng(seed)
    root = rng.normal(size=(n, n))
    P = np.diag(rng.uniform(0.1, 2.0, n)) if sparse else root @ root.T
    K = rng.normal(size=(n, 3))
    if sparse:
        K[rng.uniform(size=K.shape) < 0.5] = 0.0
    H = rng.normal(size=(3, n))
    H[:, 3:6] = 0.0
    IK = np.eye(n) - K @ H
    IK[:, 3:6] = np.eye(n)[:, 3:6]      # exactly the identity's, as the kernel makes them
    R = np.diag(rng.uniform(0.1, 1.0, 3))
    return P, IK, K @ R @ K.T


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([6, 9]), sparse=st.booleans())
def test_the_joseph_shortcut_keeps_every_bit_of_the_full_product(seed, n, sparse):
    P, IK, KRK = _joseph_inputs(seed, n, sparse)
    full, short = P.copy(), P.copy()
    joseph_covariance(full, IK, KRK, np.empty((n, n)), n, False)
    joseph_covariance(short, IK, KRK, np.empty((n, n)), n, True)
    np.testing.assert_array_equal(short.view(np.int64), full.view(np.int64))


def test_the_shortcut_is_not_the_full_product_where_h_reads_the_bias():
    """The shortcut's premise matters: with H non-zero in the bias columns it
    gives another covariance (so the test above can tell them apart)."""
    P, IK, KRK = _joseph_inputs(0, 6, False)
    IK[:, 3:6] += 0.1
    full, short = P.copy(), P.copy()
    joseph_covariance(full, IK, KRK, np.empty((6, 6)), 6, False)
    joseph_covariance(short, IK, KRK, np.empty((6, 6)), 6, True)
    assert not np.array_equal(short, full)
