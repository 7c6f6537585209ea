"""The vector sensors' compiled arithmetic (sensors/vector_arithmetic.py)
gives the bits the numpy passes it replaced gave: those passes are kept here,
as they were, as the reference (a reading must not change when it is made by
the compiled code), down to each sensor's readings as its former numpy
``measure_runs`` made them."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from dynamics.environment import References
from sensors.accelerometer import GRAVITY_REACTION_ENU_MPS2, Accelerometer
from sensors.magnetometer import Magnetometer
from sensors.sun_sensor import FULL_SUN, FineSunSensor
from sensors.vector import normals, times_matrix, to_body
from tests.conftest import random_sky


def numpy_times_matrix(vectors, matrix):
    """The former ``sensors.vector.times_matrix``."""
    return (vectors[..., 0:1] * matrix[:, 0] + vectors[..., 1:2] * matrix[:, 1]
            + vectors[..., 2:3] * matrix[:, 2])


def former_rotated_rows(vectors, rotvecs):
    """The former ``sensors.vector_arithmetic.rotated_rows`` (Rodrigues,
    element by element, ``math``'s cosine and sine), uncompiled: the
    rotation the fine sun sensor's readings were made with."""
    out = np.empty(rotvecs.shape)
    for r in range(rotvecs.shape[0]):
        for i in range(rotvecs.shape[1]):
            t0, t1, t2 = rotvecs[r, i]
            angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            safe = angle if angle > 0.0 else 1.0
            x, y, z = t0 / safe, t1 / safe, t2 / safe
            a, b, c = vectors[r, i]
            along = x * a + y * b + z * c
            cos, sin = math.cos(angle), math.sin(angle)
            scale = along * (1.0 - cos)
            out[r, i] = (a * cos + (y * c - z * b) * sin + x * scale,
                         b * cos + (z * a - x * c) * sin + y * scale,
                         c * cos + (x * b - y * a) * sin + z * scale)
    return out


finite = st.floats(-1e3, 1e3, allow_nan=False, width=64)
shapes = st.sampled_from([(3,), (1, 3), (7, 3), (2, 5, 3), (3, 1, 2, 3)])


def same_bits(a, b):
    """Equal to the bit (a zero's sign and a NaN's too)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


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


def former_fine_sun(sensor, q_true, references, rngs, first_step):
    """The former numpy ``FineSunSensor.measure_runs``: body and flags."""
    sun_unit, illumination = references.sun_unit, references.illumination
    steps = np.flatnonzero(sensor.scheduled(len(q_true), first_step))
    s = to_body(q_true[steps], sun_unit[steps])
    delta = sensor.sigma_rad * normals(rngs, (len(steps), 3))
    delta -= np.sum(delta * s, axis=-1, keepdims=True) * s
    seen = (numpy_times_matrix(s, sensor.boresight[None])[:, 0] >=
            math.cos(math.radians(sensor.fov_deg))) & (illumination[steps] >= FULL_SUN)
    body = np.zeros((len(rngs), len(q_true), 3))
    body[:, steps] = former_rotated_rows(np.broadcast_to(s, delta.shape), delta)
    available = np.zeros(len(q_true), dtype=bool)
    available[steps[seen]] = True
    return np.where(available[:, None], body, 0.0), np.broadcast_to(available, body.shape[:2])


def former_noisy(truth_of, sigma, q_true, reference, rngs, scheduled):
    """The former numpy ``measure_runs`` of the magnetometer and the
    accelerometer: the truth plus σ times each run's noise, at ``scheduled``."""
    steps = np.flatnonzero(scheduled)
    body = np.zeros((len(rngs), len(q_true), 3))
    body[:, steps] = truth_of(to_body(q_true[steps], reference[steps])) + \
        sigma * normals(rngs, (len(steps), 3))
    return body, np.broadcast_to(scheduled, body.shape[:2])


def assert_readings(readings, body, available, sigma2):
    assert same_bits(readings.body, body)
    assert np.array_equal(readings.available, available)
    assert same_bits(readings.variance, np.where(available, sigma2, 0.0))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 4), first_step=st.integers(0, 9),
       interval=st.integers(1, 3), sigma_deg=st.sampled_from([1e-6, 0.05, 3.0, 90.0]),
       fov_deg=st.sampled_from([5.0, 70.0, 90.0]))
def test_the_fine_sun_sensor_reads_its_former_bits(seed, runs, first_step, interval,
                                                   sigma_deg, fov_deg):
    """Noise across the Sun vector, the field of view and the penumbra, in
    any block of a run: each run's readings are the numpy passes' bits."""
    q, references = random_sky(seed, 40)
    sensor = FineSunSensor(sigma_deg, interval * 0.1, 0.1, fov_deg=fov_deg)
    readings = sensor.measure_runs(q, references, [np.random.default_rng(seed + run)
                                                   for run in range(runs)], first_step)
    body, available = former_fine_sun(sensor, q, references,
                                      [np.random.default_rng(seed + run) for run in range(runs)],
                                      first_step)
    assert_readings(readings, body, available, sensor.sigma_rad ** 2)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 4), first_step=st.integers(0, 9),
       interval=st.integers(1, 3))
def test_the_magnetometer_and_accelerometer_read_their_former_bits(seed, runs, first_step,
                                                                  interval):
    """Soft iron, hard iron and the accelerometer's bias, in any block of a run."""
    q, references = random_sky(seed, 30)
    rng = np.random.default_rng(seed)
    soft_iron = np.eye(3) + 0.1 * rng.normal(size=(3, 3))
    bias = 500.0 * rng.normal(size=3)
    magnetometer = Magnetometer(120.0, interval * 0.1, 0.1, bias_nT=bias, soft_iron=soft_iron)
    accelerometer = Accelerometer(0.05, interval * 0.1, 0.1, bias_mps2=bias / 1e4)
    gravity = np.broadcast_to(GRAVITY_REACTION_ENU_MPS2, (len(q), 3))

    def generators():
        return [np.random.default_rng(seed + run) for run in range(runs)]

    scheduled = magnetometer.scheduled(len(q), first_step)
    assert_readings(magnetometer.measure_runs(q, references, generators(), first_step),
                    *former_noisy(lambda body: numpy_times_matrix(body, soft_iron) + bias,
                                  120.0, q, references.magnetic_field_nT, generators(),
                                  scheduled), 120.0 ** 2)
    assert_readings(accelerometer.measure_runs(q, references, generators(), first_step),
                    *former_noisy(lambda body: body + bias / 1e4, 0.05, q, gravity,
                                  generators(), scheduled), 0.05 ** 2)


def test_readings_written_into_views_are_the_readings_made_whole():
    """The engine's call: each sensor writes into strided views of one
    block array; what it writes is what :meth:`measure_runs` returns."""
    q, references = random_sky(11, 25)
    sensor = FineSunSensor(0.5, 0.2, 0.1)
    whole = sensor.measure_runs(q, references, [np.random.default_rng(run) for run in (0, 1)],
                                3)
    body, variance = np.zeros((2, 25, 2, 3)), np.zeros((2, 25, 2))
    available = np.zeros((2, 25, 2), dtype=bool)
    reference = sensor.measure_into(q, references, [np.random.default_rng(run) for run in (0, 1)],
                                    3, body[:, :, 1], variance[:, :, 1], available[:, :, 1])
    assert same_bits(body[:, :, 1], whole.body) and same_bits(reference, whole.reference)
    assert np.array_equal(available[:, :, 1], whole.available) and whole.available.any()
    assert same_bits(variance[:, :, 1], whole.variance)
    assert not body[:, :, 0].any() and not available[:, :, 0].any()


def test_a_zero_noise_leaves_the_sun_vector_as_it_is():
    """A zero rotation vector (its axis taken as θ itself, no division by
    zero) turns nothing: the reading is the true Sun vector's bits."""
    from sensors.vector_arithmetic import turned_rows
    s = np.array([[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]])
    body, variance = np.zeros((1, 2, 3)), np.zeros((1, 2))
    available = np.zeros((1, 2), dtype=bool)
    turned_rows(s, 0.01, np.zeros((1, 2, 3)), np.arange(2), np.ones(2, dtype=bool), 1e-4, body,
                variance, available)
    assert same_bits(body[0], s) and available.all() and same_bits(variance, np.full((1, 2), 1e-4))


def test_the_fine_sun_sensor_turns_each_reading_by_its_noise():
    """Each reading is the true Sun vector turned by |δ| (the formula's
    meaning), and unit length: the noise lies across the Sun vector."""
    q, references = random_sky(7, 50)
    references = References(references.magnetic_field_nT, references.sun_unit, np.ones(50))
    sensor = FineSunSensor(2.0, 0.1, 0.1, fov_deg=90.0)
    rng = np.random.default_rng(5)
    readings = sensor.measure_runs(q, references, [rng])
    s = to_body(q, references.sun_unit)
    seen = readings.available[0]
    assert seen.sum() > 10
    delta = sensor.sigma_rad * np.random.default_rng(5).standard_normal((50, 3))
    delta -= np.sum(delta * s, axis=-1, keepdims=True) * s
    turned = np.arccos(np.clip(np.sum(readings.body[0] * s, axis=-1), -1.0, 1.0))
    assert turned[seen] == pytest.approx(np.linalg.norm(delta, axis=-1)[seen], rel=1e-6)
    assert np.linalg.norm(readings.body[0][seen], axis=-1) == pytest.approx(1.0, abs=1e-12)


def test_a_sensor_that_defines_only_measure_runs_still_writes_into_views():
    """A vector sensor written the older way (its own ``measure_runs``) reads
    the same through ``measure_into``, as the engine calls it; one that
    defines neither says so."""
    from sensors.vector import VectorReadings, VectorSensor

    class Older(VectorSensor):
        name = "older"

        def measure_runs(self, q_true, references, rngs, first_step=0):
            shape = (len(rngs), len(q_true))
            available = np.zeros(shape, dtype=bool)
            available[:, ::2] = True
            body = np.stack([rng.standard_normal((len(q_true), 3)) for rng in rngs])
            return VectorReadings(self.name, body, np.ones((len(q_true), 3)), available,
                                  np.full(shape, 4.0))

    q, references = random_sky(2, 6)
    whole = Older(0.1, 0.1).measure_runs(q, references, [np.random.default_rng(1)])
    body, variance = np.zeros((1, 6, 2, 3)), np.zeros((1, 6, 2))
    available = np.zeros((1, 6, 2), dtype=bool)
    reference = Older(0.1, 0.1).measure_into(q, references, [np.random.default_rng(1)], 0,
                                             body[:, :, 0], variance[:, :, 0],
                                             available[:, :, 0])
    assert same_bits(reference, whole.reference)
    assert np.array_equal(available[:, :, 0], whole.available)
    assert same_bits(body[:, :, 0], np.where(whole.available[..., None], whole.body, 0.0))
    assert same_bits(variance[:, :, 0], np.where(whole.available, 4.0, 0.0))
    with pytest.raises(NotImplementedError, match="neither measure_into nor measure_runs"):
        VectorSensor(0.1, 0.1).measure_runs(q, references, [np.random.default_rng(1)])
