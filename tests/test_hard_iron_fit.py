"""The magnetometer's hard iron fitted online (estimators.imu.hard_iron):
the fit against its equations and its statistics, when it is believed,
and the filters that take it off each reading, per-run and in the kernel."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from benchmarks.broad.metric import errors_deg
from dynamics.quaternion import to_body_frame
from dynamics.validation import InvalidParameterError
from estimators import USQUE, MultiplicativeEKF
from estimators.imu import hard_iron
from estimators.smoother import MekfSmoother
from sensors.vector import VectorReadings
from tests.conftest import imu_filter_settings, turning_imu


EARTH = np.array([0.0, 20.0, -40.0])              # µT, ENU: 44.7 µT, dip 63°
MAGNET = np.array([8.0, -5.0, 12.0])              # µT, body frame: 15.3 µT


def _fitted(readings, dt=0.01):
    """The fit's state after ``readings`` (one every ``dt`` s) and the last
    reading corrected."""
    state, out = hard_iron.new_state(), np.empty(3)
    for reading in readings:
        hard_iron.step(reading, dt, state, out)
    return state, out


def _sphere(n, noise_ut, magnet, seed=1):
    """``n`` readings of the Earth's field in random attitudes, with ``magnet``
    and white noise of ``noise_ut`` per axis."""
    rng = np.random.default_rng(seed)
    turned = Rotation.random(n, random_state=seed).inv().apply(EARTH)
    return turned + magnet + rng.normal(0.0, noise_ut, (n, 3))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=6, max_size=6))
def test_the_smallest_eigenvalue_is_numpys(entries):
    # Smith's closed form loses half the digits where two eigenvalues meet
    # (acos near ±1): an error of order √ε ≈ 1.5e-8 of the matrix's scale.
    xx, xy, xz, yy, yz, zz = entries
    matrix = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    expected = np.linalg.eigvalsh(matrix)[0]
    scale = max(np.abs(matrix).max(), 1.0)
    assert abs(hard_iron.smallest_eigenvalue(np.array(entries)) - expected) <= 1e-7 * scale


def test_the_fitted_hard_iron_is_within_its_standard_error():
    # Readings on a sphere in uniformly random attitudes, noise σ per axis:
    # the radial residual has σ, the readings' covariance is |B|²/3 I, so
    # the least-squares centre errs by σ √(3 / N) per axis, N the effective
    # number of readings of the exponential memory, (Σw)² / Σw² =
    # (1 + λ) / (1 − λ) for λ = e^(−T/τ). Summed over 20 seeds, its squared
    # error over that variance is χ² with 60 degrees of freedom: within its
    # two-sided 99 % band. The same errors read as a memory four times
    # longer (N four times larger: a fit claiming half its error) fall out.
    dt, sigma, seeds = 0.01, 0.2, 20
    decay = math.exp(-dt / hard_iron.TIME_CONSTANT_S)
    variance = 3 * sigma ** 2 / ((1 + decay) / (1 - decay))
    total = 0.0
    for seed in range(seeds):
        state, _ = _fitted(_sphere(3000, sigma, MAGNET, seed=10 + seed), dt)
        error = hard_iron.applied(state) - MAGNET
        total += error @ error / variance
    low, high = chi2.ppf([0.005, 0.995], 3 * seeds)
    assert low < total < high, (total, low, high)
    assert not low < 4 * total < high


def test_without_a_magnet_no_hard_iron_is_applied():
    state, out = _fitted(_sphere(3000, 0.4, np.zeros(3)))
    assert np.all(hard_iron.applied(state) == 0.0)
    assert state[hard_iron.RADIUS] > 0.0            # it did fit: it found nothing to remove


def test_a_ring_of_readings_is_not_believed():
    # A turn about one axis: the centre's component along it is undetermined.
    turns = Rotation.from_rotvec(np.outer(np.linspace(0, 12 * np.pi, 3000), [0.0, 0.0, 1.0]))
    state, out = _fitted(turns.inv().apply(EARTH) + MAGNET)
    assert np.all(hard_iron.applied(state) == 0.0)
    spread_free = _fitted(_sphere(3000, 0.0, MAGNET))[0]      # the same magnet, every direction
    np.testing.assert_allclose(hard_iron.applied(spread_free), MAGNET, atol=1e-6)


def test_a_field_that_is_not_one_field_is_not_believed():
    # The world's field itself changing by a third while the body turns: no
    # sphere holds the readings (residual far above MAX_RESIDUAL).
    readings = _sphere(3000, 0.0, MAGNET)
    readings *= 1.0 + 0.3 * np.sin(np.arange(3000) / 7.0)[:, None]
    state, _ = _fitted(readings)
    assert np.all(hard_iron.applied(state) == 0.0)


def test_a_magnet_put_on_and_taken_off_is_followed():
    on = _sphere(2000, 0.2, MAGNET, seed=2)
    off = _sphere(4000, 0.2, np.zeros(3), seed=3)
    state, out = _fitted(on)
    np.testing.assert_allclose(hard_iron.applied(state), MAGNET, atol=0.1)
    for reading in off:                          # 40 s, eight time constants
        hard_iron.step(reading, 0.01, state, out)
    assert np.all(hard_iron.applied(state) == 0.0)
    np.testing.assert_array_equal(out, off[-1])


def _believed_after(readings, start: int, dt: float = 0.01) -> float:
    """Seconds after reading ``start`` until the fit applies a hard iron
    within 0.2 µT of :data:`MAGNET` (inf: never)."""
    state, out = hard_iron.new_state(), np.empty(3)
    for k, reading in enumerate(readings):
        hard_iron.step(reading, dt, state, out)
        if k >= start and np.linalg.norm(hard_iron.applied(state) - MAGNET) < 0.2:
            return (k - start) * dt
    return math.inf


def test_a_magnet_put_on_is_fitted_soon_after_it_sits_still():
    # 10 s without a magnet, 2 s of a magnet being put on (readings off any
    # sphere: a field twice the Earth's swinging about), then 30 s with it
    # fixed. The transient's readings, however faded, held the residual
    # beyond MAX_RESIDUAL for some 20 s; the fit now forgets them once its
    # residual has been beyond its bound for RESTART_S, and is believed
    # within RESTART_S plus the few seconds a fresh fit takes (3.5 s here;
    # before, not within the 30 s). Without the transient it is believed
    # within the same bound (5.9 s: the readings without the magnet lie off
    # the new sphere too), and the transient alone, 30 s long, restarting
    # the fit every RESTART_S (nothing fixed to fit), leaves no hard iron
    # applied.
    before = _sphere(1000, 0.2, np.zeros(3), seed=4)
    # (three frequencies: a swing in a plane leaves no fit to judge at all)
    swing = 2 * np.linalg.norm(EARTH) * np.sin(np.arange(200)[:, None] / 5.0
                                               * [1.0, 1.37, 1.91])
    after = _sphere(3000, 0.2, MAGNET, seed=5)
    with_transient = _believed_after(np.concatenate([before, swing, after]), 1200)
    assert with_transient < hard_iron.RESTART_S + 4.0, with_transient
    assert _believed_after(np.concatenate([before, after]), 1000) < hard_iron.RESTART_S + 4.0
    state, _ = _fitted(np.concatenate([before, np.tile(swing, (15, 1))]))
    assert np.all(hard_iron.applied(state) == 0.0)


@pytest.mark.parametrize("magnet_stays", [False, True])
def test_a_magnet_taken_off_before_a_rest_is_dropped_without_a_new_fit(magnet_stays):
    # At rest no fit can be made (no spread): the hard iron is dropped
    # because the readings' own norm is the field's and their norm less it
    # is not, for MIN_GONE_S; a magnet that stays on keeps it.
    dt = 0.01
    state, out = _fitted(_sphere(2000, 0.2, MAGNET, seed=2), dt)
    still = Rotation.random(random_state=7).inv().apply(EARTH) + (MAGNET if magnet_stays else 0)
    steps = int(hard_iron.MIN_GONE_S / dt)
    for k in range(3 * steps):
        hard_iron.step(still, dt, state, out)
        if k == steps - 3:                          # not yet: the hold time
            assert np.linalg.norm(hard_iron.applied(state)) > 0.5 * np.linalg.norm(MAGNET)
    if magnet_stays:
        np.testing.assert_allclose(hard_iron.applied(state), MAGNET, atol=0.1)
    else:
        assert np.all(hard_iron.applied(state) == 0.0)
        np.testing.assert_array_equal(out, still)


# --- the filters ---------------------------------------------------------------------


def _tumbling(dt: float, n: int, magnet_until: int):
    """A body turning on three axes, its biased gyro and true attitude, and
    its accelerometer and magnetometer (a quarter rate) with :data:`MAGNET`
    on the device for its first ``magnet_until`` samples."""
    rng = np.random.default_rng(5)
    t = np.arange(n) * dt
    rate = np.stack([1.5 * np.sin(0.7 * t), 1.2 * np.cos(1.1 * t), 0.8 * np.sin(0.3 * t + 1)], 1)
    gyro, q, acc = turning_imu(rate, dt, rng)
    acc += rng.normal(0, 0.3, (n, 3))
    mag = np.array([to_body_frame(qk, EARTH) for qk in q]) + rng.normal(0, 0.3, (n, 3))
    mag[:magnet_until] += MAGNET
    every = np.arange(n) % 4 == 0
    vectors = tuple(VectorReadings(sensor=name, body=body, reference=np.tile(ref, (n, 1)),
                                   available=np.ones(n, bool) if name == "accelerometer"
                                   else every, variance=np.full(n, 0.1), dof=3,
                                   reference_known=name == "accelerometer")
                    for name, body, ref in (("accelerometer", acc, [0.0, 0.0, 9.81]),
                                            ("magnetometer", mag, EARTH)))
    return gyro, q, vectors


def _settings(dt: float, fit: bool) -> dict:
    return imu_filter_settings(dt, hard_iron_fit=fit)


def _heading_rms_deg(filter_class, fit, gyro, truth, vectors, after):
    """The heading's RMS error from sample ``after`` on, the run on the
    kernel (held to the per-run path below)."""
    from benchmarks.engine.recorded import run_recorded
    estimates = run_recorded(filter_class(**_settings(1 / 200, fit)), gyro, vectors).estimates
    return float(np.sqrt(np.mean(errors_deg(estimates, truth)["heading"][after:] ** 2)))


@pytest.mark.parametrize("filter_class", [MultiplicativeEKF, USQUE])
def test_with_a_magnet_on_the_device_the_fit_holds_the_heading(filter_class):
    # The magnet throughout, no rest: the field turns with the body, and the
    # heading model without the fit rejects it (it holds no heading). With
    # the fit, the heading after 10 s is within 0.2° of what it is without
    # any magnet (MEKF 0.49° against 0.53°, USQUE 0.30° against 0.22°;
    # unfitted 13–14°). Without a magnet the fit finds none to remove: the
    # run is the unfitted one.
    dt, n = 1 / 200, 6000
    gyro, truth, clean = _tumbling(dt, n, magnet_until=0)
    _, _, magnet = _tumbling(dt, n, magnet_until=n)
    without_magnet = _heading_rms_deg(filter_class, True, gyro, truth, clean, 2000)
    assert without_magnet == _heading_rms_deg(filter_class, False, gyro, truth, clean, 2000)
    fitted = _heading_rms_deg(filter_class, True, gyro, truth, magnet, 2000)
    unfitted = _heading_rms_deg(filter_class, False, gyro, truth, magnet, 2000)
    assert fitted < without_magnet + 0.2
    assert unfitted > 5 * fitted


@pytest.mark.parametrize("filter_class", [
    MultiplicativeEKF, pytest.param(USQUE, marks=pytest.mark.slow),    # its per-run path: 5 s
    pytest.param(MekfSmoother, marks=pytest.mark.slow)])               # two passes: 3 s
def test_the_kernel_fits_the_hard_iron_as_the_per_run_filter_does(filter_class):
    from benchmarks.engine.recorded import run_recorded
    dt, n = 1 / 200, 4000
    gyro, _, vectors = _tumbling(dt, n, magnet_until=2400)       # taken off at 12 s
    per_run = filter_class(**_settings(dt, True))
    reference = per_run.run(gyro, np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros(n, bool),
                            vectors=vectors)
    run = run_recorded(filter_class(**_settings(dt, True)), gyro, vectors)
    assert run.path == "kernel"
    np.testing.assert_allclose(run.estimates, reference, rtol=0, atol=1e-9)
    unfitted = run_recorded(filter_class(**_settings(dt, False)), gyro, vectors).estimates
    assert np.abs(unfitted - reference).max() > 1e-3          # the fit was at work
    if filter_class is not MekfSmoother:
        assert run.rejected == dict(per_run.rejected)


def test_the_fit_needs_the_heading_model():
    with pytest.raises(InvalidParameterError, match="hard_iron_fit.*magnetometer_model"):
        MultiplicativeEKF(hard_iron_fit=True)
    with pytest.raises(InvalidParameterError, match="hard_iron_fit.*boolean"):
        MultiplicativeEKF(magnetometer_model="heading", hard_iron_fit="yes")


def test_on_a_shipped_undisturbed_trial_the_fit_finds_no_hard_iron_to_remove():
    # BROAD's trial 02 (no magnet near the board, undisturbed): the fit is
    # believed while the IMU turns, and finds the centre within what its
    # residual explains every time, so the MEKF is bit for bit the one
    # without it. A magnet's 10 µT added to the same readings is found, to
    # within what the room's field and the soft iron put on a fit of 5 s
    # (its centre moves by about 1 µT from one stretch of turns to another).
    from benchmarks.broad.dataset import open_broad
    from benchmarks.broad.inputs import imu_inputs
    from benchmarks.engine.recorded import run_recorded
    from benchmarks.shipped import shipped_file
    dataset = open_broad(shipped_file("datasets/broad/trials.json").parent)
    inputs = imu_inputs(dataset.load(dataset.trial_name("02")))
    omega, vectors = inputs.sensors.omega_meas_radps, inputs.sensors.vectors

    def estimates(fit, readings):
        mekf = MultiplicativeEKF.from_scenario(inputs.scenario, hard_iron_fit=fit)
        return run_recorded(mekf, omega, readings).estimates

    np.testing.assert_array_equal(estimates(True, vectors), estimates(False, vectors))
    field = next(v for v in vectors if v.sensor == "magnetometer")
    state, _ = _fitted(field.body[field.available] + [6.0, -8.0, 0.0], inputs.scenario.dt)
    np.testing.assert_allclose(hard_iron.applied(state), [6.0, -8.0, 0.0], atol=1.5)


def test_a_slow_magnetometer_is_fitted_too_and_a_non_finite_reading_is_passed_over():
    # At 5 Hz the fit's memory of 5 s holds about 25 readings' weight: the
    # fit begins after MIN_READINGS readings all the same (20 s here).
    state, _ = _fitted(_sphere(150, 0.2, MAGNET), dt=0.2)
    np.testing.assert_allclose(hard_iron.applied(state), MAGNET, atol=0.3)
    before, out = state.copy(), np.empty(3)
    hard_iron.step(np.array([np.nan, 1.0, 2.0]), 0.2, state, out)
    np.testing.assert_array_equal(state, before)
    assert np.isnan(out[0]) and out[1] == 1.0 - hard_iron.applied(state)[1]
