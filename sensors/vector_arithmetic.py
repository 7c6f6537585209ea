r"""The vector sensors' element-by-element arithmetic, compiled: the products
of vectors with a sensor's matrix (a magnetometer's soft iron, the coarse sun
sensors' face normals, a boresight), each run's noise added to the truth and
written where the engine keeps the readings, and the fine sun sensor's
rotation of each Sun vector by its noise (Rodrigues' formula, Markley &
Crassidis 2014, §2.7.1).

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


@njit(cache=True, inline="always")
def _rotated(a, b, c, t0, t1, t2):
    """The vector (a, b, c) rotated by the rotation vector (t0, t1, t2)."""
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    safe = angle if angle > 0.0 else 1.0
    x, y, z = t0 / safe, t1 / safe, t2 / safe
    along = x * a + y * b + z * c
    cos, sin = math.cos(angle), math.sin(angle)
    scale = along * (1.0 - cos)
    return (a * cos + (y * c - z * b) * sin + x * scale,
            b * cos + (z * a - x * c) * sin + y * scale,
            c * cos + (x * b - y * a) * sin + z * scale)


@njit(cache=True, nogil=True)
def noisy_rows(truth, sigma, noise, steps, variance_value, body, variance, available):
    """Each run's readings ``truth + σ·noise`` at ``steps``, written in place:
    ``body[r, steps[m]] = truth[m] + sigma * noise[r, m]`` (``truth`` ``(M,
    3)``, ``noise`` ``(R, M, 3)``), with the reading's variance and flag."""
    for r in range(noise.shape[0]):
        for m in range(len(steps)):
            k = steps[m]
            for i in range(3):
                body[r, k, i] = truth[m, i] + sigma * noise[r, m, i]
            variance[r, k] = variance_value
            available[r, k] = True


@njit(cache=True, nogil=True)
def turned_rows(s, sigma, noise, steps, seen, variance_value, body, variance, available):
    r"""The fine sun sensor's readings, written in place: at each step
    ``steps[m]`` that is ``seen``, the true Sun vector ``s[m]`` turned by the
    noise δ = σ·noise[r, m] less its component along ``s[m]`` (δ ⟂ s:
    :mod:`sensors.sun_sensor`). The projection sums ``δ·s`` as numpy's
    reduction over three elements does, ``(p₀ + p₁) + p₂``."""
    for r in range(noise.shape[0]):
        for m in range(len(steps)):
            if not seen[m]:
                continue
            s0, s1, s2 = s[m, 0], s[m, 1], s[m, 2]
            d0, d1, d2 = sigma * noise[r, m, 0], sigma * noise[r, m, 1], sigma * noise[r, m, 2]
            along = d0 * s0 + d1 * s1 + d2 * s2
            d0, d1, d2 = d0 - along * s0, d1 - along * s1, d2 - along * s2
            k = steps[m]
            body[r, k, 0], body[r, k, 1], body[r, k, 2] = _rotated(s0, s1, s2, d0, d1, d2)
            variance[r, k] = variance_value
            available[r, k] = True
