"""The vector sensors' compiled arithmetic (sensors/vector_arithmetic.py)
gives the bits the numpy passes it replaced gave: those passes are kept here,
as they were, as the reference (a reading must not change when it is made by
the compiled code)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from sensors.sun_sensor import _rotated
from sensors.vector import times_matrix


def numpy_times_matrix(vectors, matrix):
    """The former ``sensors.vector.times_matrix``."""
    return (vectors[..., 0:1] * matrix[:, 0] + vectors[..., 1:2] * matrix[:, 1]
            + vectors[..., 2:3] * matrix[:, 2])


def numpy_rotated(vectors, rotvecs):
    """The former ``sensors.sun_sensor._rotated`` (Rodrigues, numpy passes)."""
    angle = np.sqrt(np.sum(rotvecs * rotvecs, axis=-1, keepdims=True))
    safe = np.where(angle > 0.0, angle, 1.0)
    axis = rotvecs / safe
    x, y, z = axis[..., 0:1], axis[..., 1:2], axis[..., 2:3]
    a, b, c = vectors[..., 0:1], vectors[..., 1:2], vectors[..., 2:3]
    cross = np.concatenate([y * c - z * b, z * a - x * c, x * b - y * a], axis=-1)
    along = x * a + y * b + z * c
    cos, sin = np.cos(angle), np.sin(angle)
    return vectors * cos + cross * sin + axis * (along * (1.0 - cos))


finite = st.floats(-1e3, 1e3, allow_nan=False, width=64)
shapes = st.sampled_from([(3,), (1, 3), (7, 3), (2, 5, 3), (3, 1, 2, 3)])


def same_bits(a, b):
    """Equal to the bit, NaN where NaN."""
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


@settings(max_examples=60, deadline=None)
@given(data=st.data(), shape=shapes, rows=st.integers(1, 7))
def test_times_matrix_is_the_numpy_passes_to_the_bit(data, shape, rows):
    vectors = data.draw(arrays(float, shape, elements=finite))
    matrix = data.draw(arrays(float, (rows, 3), elements=finite))
    assert same_bits(times_matrix(vectors, matrix), numpy_times_matrix(vectors, matrix))


def test_times_matrix_keeps_nan_rows_and_views():
    """An unsolved reading (NaN) stays NaN; a strided view reads as its copy."""
    rng = np.random.default_rng(3)
    vectors = rng.normal(size=(40, 6))[:, ::2]
    vectors[5] = np.nan
    matrix = rng.normal(size=(6, 3))
    result = times_matrix(vectors, matrix)
    assert np.isnan(result[5]).all() and np.isfinite(np.delete(result, 5, axis=0)).all()
    assert same_bits(result, numpy_times_matrix(vectors, matrix))


@settings(max_examples=60, deadline=None)
@given(data=st.data(), shape=shapes, scale=st.sampled_from([0.0, 1e-9, 1e-3, 0.5, 4.0]))
def test_rotation_is_the_numpy_passes_to_the_bit(data, shape, scale):
    vectors = data.draw(arrays(float, shape, elements=finite))
    rotvecs = scale * data.draw(arrays(float, shape, elements=st.floats(-1, 1, width=64)))
    assert same_bits(_rotated(vectors, rotvecs), numpy_rotated(vectors, rotvecs))


def test_rotation_broadcasts_the_truth_over_the_runs():
    """The fine sun sensor's call: one truth ``(T, 3)`` broadcast over the runs'
    noises ``(R, T, 3)``; each run's rows as its own call's, and a rotation
    by θ about an axis across ``v`` turns it by |θ| (the formula's meaning)."""
    rng = np.random.default_rng(7)
    truth = rng.normal(size=(50, 3))
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    noise = 1e-2 * rng.normal(size=(4, 50, 3))
    noise -= np.sum(noise * truth, axis=-1, keepdims=True) * truth
    stacked = _rotated(np.broadcast_to(truth, noise.shape), noise)
    assert same_bits(stacked, numpy_rotated(np.broadcast_to(truth, noise.shape), noise))
    for run in range(4):
        assert same_bits(stacked[run], _rotated(truth, noise[run]))
    turned = np.arccos(np.clip(np.sum(stacked * truth, axis=-1), -1.0, 1.0))
    assert turned == pytest.approx(np.linalg.norm(noise, axis=-1), rel=1e-6)
