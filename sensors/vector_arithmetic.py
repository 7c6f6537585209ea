r"""The vector sensors' element-by-element arithmetic, compiled: the products
of vectors with a sensor's matrix (a magnetometer's soft iron, the coarse sun
sensors' face normals, a boresight) and the fine sun sensor's rotation of
each Sun vector by its noise (Rodrigues' formula, Markley & Crassidis 2014,
§2.7.1).

Why compiled: a campaign measures every run's readings at every scheduled
step (a thousand CubeSat runs of one orbit: six million sets of currents, six
million Sun vectors rotated), and numpy runs these formulas as a dozen
whole-array passes, each writing a temporary array as large as the readings;
in a CubeSat campaign those passes were a third of the readings' time. Each
product and sum here is the one numpy's passes made, in the same order, so
every reading keeps its bits (``tests/test_vector_arithmetic.py`` holds them
to the numpy passes, kept there as the reference). The loops are serial and
release the GIL, as :mod:`sensors.sun_faces`' do: the engine makes the next
block's readings in a thread beside its kernels.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def times_matrix_rows(vectors, matrix):
    """``(M, K)``: each of ``vectors`` ``(M, 3)`` times each row of ``matrix``
    ``(K, 3)``, summed ``(v₀m₀ + v₁m₁) + v₂m₂``."""
    out = np.empty((vectors.shape[0], matrix.shape[0]))
    for i in range(vectors.shape[0]):
        v0, v1, v2 = vectors[i, 0], vectors[i, 1], vectors[i, 2]
        for j in range(matrix.shape[0]):
            out[i, j] = v0 * matrix[j, 0] + v1 * matrix[j, 1] + v2 * matrix[j, 2]
    return out


@njit(cache=True, nogil=True)
def rotated_rows(vectors, rotvecs):
    r"""``(R, M, 3)``: each of ``vectors`` ``(R, M, 3)`` rotated by its rotation
    vector θ of ``rotvecs`` (same shape; either may be a broadcast view),
    :math:`v\cos\theta + (\hat k\times v)\sin\theta + \hat k(\hat k\cdot
    v)(1-\cos\theta)`, a zero rotation vector's axis taken as θ itself."""
    out = np.empty(rotvecs.shape)
    for r in range(rotvecs.shape[0]):
        for i in range(rotvecs.shape[1]):
            t0, t1, t2 = rotvecs[r, i, 0], rotvecs[r, i, 1], rotvecs[r, i, 2]
            angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            safe = angle if angle > 0.0 else 1.0
            x, y, z = t0 / safe, t1 / safe, t2 / safe
            a, b, c = vectors[r, i, 0], vectors[r, i, 1], vectors[r, i, 2]
            along = x * a + y * b + z * c
            cos, sin = math.cos(angle), math.sin(angle)
            scale = along * (1.0 - cos)
            out[r, i, 0] = a * cos + (y * c - z * b) * sin + x * scale
            out[r, i, 1] = b * cos + (z * a - x * c) * sin + y * scale
            out[r, i, 2] = c * cos + (x * b - y * a) * sin + z * scale
    return out
