"""Every channel turns as the gyro says (sensors.turning): a reference in the
wrong order or convention, a magnetometer's axes in the wrong order, and a
reference mounted apart from the IMU are told apart from a right declaration.
Exact tier: constructed motions whose turning is known."""
import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from dynamics.validation import InvalidParameterError
from sensors.recording import load_recording
from sensors.turning import (AXES_DECLARED_BELOW, AXES_OTHER_ABOVE, ORDERS,
                             REFERENCE_UNEXPLAINED, axes_fit, clock_offset, first_fitting,
                             reference_fit, reference_fits)

RATE_HZ = 200.0
DT = 1.0 / RATE_HZ
FIELD_ENU_UT = np.array([0.0, 22.0, -42.0])      # a field of 47 µT, dip 62°


def _motion(seconds: float = 30.0, scale: float = 1.0):
    """A body turning about every axis (rates up to ~1.5 rad/s times
    ``scale``): the gyro's rates and the attitude (body → world) they make."""
    t = np.arange(int(seconds * RATE_HZ)) * DT
    rates = scale * np.stack([0.9 * np.sin(0.7 * t), 0.7 * np.sin(1.1 * t + 1.0),
                              0.5 * np.cos(0.5 * t)], axis=1)
    steps = Rotation.from_rotvec(rates * DT)     # reading k: the interval before sample k
    attitude = [Rotation.identity()]
    for step in steps[1:]:
        attitude.append(attitude[-1] * step)
    return rates, Rotation.concatenate(attitude)


@pytest.fixture(scope="module")
def motion():
    return _motion()


def _quat(attitude):
    return attitude.as_quat(scalar_first=True)


def test_the_gyros_own_body_fits_with_nothing_unexplained(motion):
    rates, attitude = motion
    unexplained, rotation = reference_fit(rates, _quat(attitude), DT)
    assert unexplained < 1e-4
    assert np.degrees(rotation.magnitude()) < 0.05
    assert reference_fits((unexplained, rotation))


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), st.floats(2.0, 170.0))
def test_a_reference_mounted_apart_is_found_turned_by_its_mounting(motion, axis, angle_deg):
    """For any fixed rotation between the reference's axes and the IMU's,
    the fit finds its angle and explains all the turning."""
    axis = np.asarray(axis)
    if np.linalg.norm(axis) < 0.1:
        axis = np.array([0.0, 0.0, 1.0])
    mounting = Rotation.from_rotvec(np.radians(angle_deg) * axis / np.linalg.norm(axis))
    rates, attitude = motion
    unexplained, rotation = reference_fit(rates, _quat(attitude * mounting), DT)
    assert unexplained < 1e-4
    assert abs(np.degrees(rotation.magnitude()) - angle_deg) < 0.05


def test_the_wrong_order_and_the_inverse_are_refused_and_the_right_one_found(motion):
    rates, attitude = motion
    quat = _quat(attitude)
    for wrong in (np.roll(quat, -1, axis=1), quat * [1.0, -1.0, -1.0, -1.0]):
        fit = reference_fit(rates, wrong, DT)
        assert fit[0] > REFERENCE_UNEXPLAINED
        assert not reference_fits(fit)
    candidates = [("scalar first", np.roll(quat, -1, axis=1)), ("as given", quat)]
    assert first_fitting(rates, candidates, DT) == "as given"
    assert first_fitting(rates, candidates[:1], DT) is None


@pytest.mark.parametrize("bias_degps", [1.0, 5.0])
def test_a_gyro_bias_is_fitted_not_read_as_a_wrong_reference(bias_degps):
    """A MEMS gyro's bias of degrees a second, on a slow motion (0.2 rad/s),
    leaves the reference explained: the bias is fitted with the rotation."""
    rates, attitude = _motion(scale=0.2)
    biased = rates + np.radians(bias_degps) * np.array([0.6, 0.0, -0.8])
    unexplained, rotation = reference_fit(biased, _quat(attitude), DT)
    assert unexplained < 0.01 and np.degrees(rotation.magnitude()) < 0.5


def test_a_reference_that_never_turns_is_all_unexplained(motion):
    rates, _ = motion
    fit = reference_fit(rates, _quat(Rotation.identity(len(rates))), DT)
    assert fit == (1.0, None) and not reference_fits(fit)


def _late_reference_npz(folder, seconds_late: float):
    """A fast motion's archive whose reference attitudes come late."""
    rates, attitude = _motion(scale=3.0)
    late = int(seconds_late * RATE_HZ)
    quat = _quat(attitude)
    shifted = np.concatenate([np.repeat(quat[:1], late, axis=0), quat[:-late]])
    path = folder / "trial.npz"
    np.savez(path, imu_gyr_radps=rates, opt_quat=shifted,
             movement=np.ones(len(rates), dtype=bool), sampling_rate_hz=np.array(RATE_HZ))
    return path


def test_a_reference_that_fits_nothing_is_warned_of_not_refused(tmp_path):
    """Turning unlike the gyro with no other declaration fitting (here a
    clock 1 s off the gyro's, beyond the offsets tried) is a warning naming
    what to check: no key declares a clock's offset."""
    with pytest.warns(UserWarning, match=r"opt_quat turns unlike the gyro \(\d+ % .*check the "
                      r"reference's convention, its axes against the IMU's and its clock"):
        load_recording(_late_reference_npz(tmp_path, 1.0))


def test_a_reference_clock_behind_the_gyros_is_found(tmp_path):
    """A reference whose attitudes come 0.45 s late turns unlike the gyro
    (14 % unexplained); shifted by its offset it fits, and the note says
    by how much."""
    with pytest.warns(UserWarning, match=r"opt_quat turns unlike the gyro .*: its clock 450 ms "
                      r"behind the gyro's would explain it \(0\.0 % unexplained then\)"):
        load_recording(_late_reference_npz(tmp_path, 0.45))


def test_a_clock_offset_is_found_to_the_sample(motion):
    """Each reading is the rate over the interval before its sample (an
    IMU's, as the filters take it): a reference 60 ms late is found 60 ms
    late, not a sample less (the check had read each rate as the interval
    after its sample), and on time leaves nothing unexplained."""
    rates, attitude = motion
    quat = _quat(attitude)
    late = 12                                      # samples: 60 ms at 200 Hz
    shifted = np.concatenate([np.repeat(quat[:1], late, axis=0), quat[:-late]])
    offset, unexplained = clock_offset(rates, shifted, DT)
    assert offset == pytest.approx(late * DT) and unexplained < 1e-6
    assert reference_fit(rates, quat, DT)[0] < 1e-6


def test_too_little_turning_or_reference_is_no_evidence(motion):
    rates, attitude = motion
    still = np.zeros_like(rates)
    assert reference_fit(still, _quat(Rotation.identity(len(rates))), DT) is None
    hidden = _quat(attitude).copy()
    hidden[:-int(0.5 * RATE_HZ)] = np.nan        # the markers seen only for 0.5 s
    assert reference_fit(rates, hidden, DT) is None
    assert reference_fits(None)


def test_a_turn_about_one_axis_leaves_the_mounting_undetermined():
    t = np.arange(int(20 * RATE_HZ)) * DT
    rates = np.zeros((len(t), 3))
    rates[:, 2] = np.sin(0.8 * t)
    attitude = Rotation.from_rotvec(np.outer(np.cumsum(rates[:, 2]) * DT, [0, 0, 1]))
    unexplained, rotation = reference_fit(rates, _quat(attitude), DT)
    assert unexplained < 1e-3 and rotation is None


def _field(attitude, hard_iron_uT=np.zeros(3)):
    """The Earth's field seen from the body, plus a hard iron."""
    return attitude.inv().apply(FIELD_ENU_UT) + hard_iron_uT


@pytest.mark.parametrize("hard_iron_uT", [0.0, 46.0, 150.0])
def test_a_hard_iron_neither_hides_wrong_axes_nor_flags_right_ones(motion, hard_iron_uT):
    """A constant offset is fitted with each order: the right axes pass and
    a swap of two is found, however large the hard iron (an uncalibrated
    phone's reaches tens of µT, beyond the field's 47)."""
    rates, attitude = motion
    hard_iron = hard_iron_uT * np.array([0.6, -0.64, 0.48])
    assert axes_fit(rates, _field(attitude, hard_iron), DT) is None
    fit = axes_fit(rates, _field(attitude, hard_iron)[:, [1, 0, 2]], DT)
    assert fit is not None and fit[2] > AXES_OTHER_ABOVE
    assert np.allclose(np.abs(fit[1]), [[0, 1, 0], [1, 0, 0], [0, 0, 1]])


@settings(max_examples=30, deadline=None)
@given(st.integers(0, len(ORDERS) - 1), st.booleans())
def test_wrong_axes_are_found_and_undone(motion, index, negated):
    """Readings in any other order of the axes, right- or left-handed: the
    order proposed undoes it, up to the sign a vector's turning cannot
    show."""
    order = ORDERS[index] * (-1.0 if negated else 1.0)
    # ±identity is the right axes: drawn again, not passed.
    assume(not (np.allclose(np.abs(np.diag(order)), 1.0)
                and np.allclose(np.diag(order), order[0, 0])))
    rates, attitude = motion
    fit = axes_fit(rates, _field(attitude) @ order.T, DT)
    assert fit is not None
    declared, better, correlation = fit
    assert correlation > AXES_OTHER_ABOVE and declared < AXES_DECLARED_BELOW
    undone = better @ order
    assert np.allclose(undone, np.eye(3)) or np.allclose(undone, -np.eye(3))


def test_a_magnetometer_reading_once_a_second_is_judged():
    """Blocks span a reading and a half at least: a 1 Hz magnetometer
    beside a 200 Hz gyro, its x and y swapped, is found (a minute of
    turning: forty blocks)."""
    rates, attitude = _motion(seconds=60.0)
    field = np.zeros((len(rates), 3))
    field[::int(RATE_HZ)] = _field(attitude)[::int(RATE_HZ)][:, [1, 0, 2]]
    fit = axes_fit(rates, field, DT)
    assert fit is not None and np.allclose(np.abs(fit[1]), [[0, 1, 0], [1, 0, 0], [0, 0, 1]])


def test_readings_slower_than_the_gyro_are_held_between(motion):
    rates, attitude = motion
    field = _field(attitude)[:, [1, 2, 0]]
    sparse = np.zeros_like(field)
    sparse[::4] = field[::4]                     # a magnetometer at a quarter of the gyro's rate
    fit = axes_fit(rates, sparse, DT)
    assert fit is not None and fit[2] > AXES_OTHER_ABOVE


def test_an_npz_reference_scalar_last_is_refused_naming_the_fix(tmp_path):
    rates, attitude = _motion()
    quat = _quat(attitude)
    arrays = dict(imu_gyr_radps=rates, movement=np.ones(len(rates), dtype=bool),
                  sampling_rate_hz=np.array(RATE_HZ))
    path = tmp_path / "trial.npz"
    np.savez(path, opt_quat=np.roll(quat, -1, axis=1), **arrays)
    with pytest.raises(InvalidParameterError, match=r"opt_quat turns unlike the gyro "
                       r"\(\d+ % .*read as \[x, y, z, w\] it would fit"):
        load_recording(path)
    np.savez(path, opt_quat=_quat(attitude * Rotation.from_euler("z", 20, degrees=True)),
             **arrays)
    with pytest.warns(UserWarning, match="opt_quat turns as the gyro only with its axes "
                      "turned 20.0° from the gyro's"):
        load_recording(path)
    np.savez(path, opt_quat=quat, **arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.allclose(load_recording(path).reference_quat, quat)


@pytest.mark.parametrize("hz", [pytest.param(5.0, marks=pytest.mark.slow), 2.0])
def test_an_accelerometer_slower_than_the_windows_is_compared_reading_to_reading(hz):
    """A simulated hand-held IMU's accelerometer kept at a few hertz turns
    as its gyro says (correlation near 1, scale near 1), compared reading to
    reading; its readings held into the 0.1 s windows had made a staircase
    (0.54 and 0.77 at 5 Hz, 0.12 at 2 Hz), and the unit and mirror checks
    were skipped without a word."""
    from sensors.handheld import simulated_recording
    from sensors.turning import gravity_turning
    recording = simulated_recording(0)
    force = recording.accelerometer_mps2.copy()
    force[np.arange(len(force)) % int(round(recording.rate_hz / hz)) != 0] = 0.0
    correlation, scale = gravity_turning(recording.gyro_radps, force, recording.dt)
    assert correlation > 0.95 and abs(scale - 1.0) < 0.1     # a unit is 57 or 9.8 times off
