"""Every channel turns as the gyro says (sensors.turning): a reference in the
wrong order or convention, a magnetometer's axes in the wrong order, and a
reference mounted apart from the IMU are told apart from a right declaration.
Exact tier: constructed motions whose turning is known."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from dynamics.validation import InvalidParameterError
from sensors.recording import load_recording
from sensors.turning import (AXES_DECLARED_BELOW, AXES_OTHER_ABOVE, REFERENCE_UNEXPLAINED,
                             _orders, axes_fit, first_fitting, reference_fit, reference_fits)

RATE_HZ = 200.0
DT = 1.0 / RATE_HZ
FIELD_ENU_UT = np.array([0.0, 22.0, -42.0])      # a field of 47 µT, dip 62°


def _motion(seconds: float = 30.0, scale: float = 1.0):
    """A body turning about every axis (rates up to ~1.5 rad/s times
    ``scale``): the gyro's rates and the attitude (body → world) they make."""
    t = np.arange(int(seconds * RATE_HZ)) * DT
    rates = scale * np.stack([0.9 * np.sin(0.7 * t), 0.7 * np.sin(1.1 * t + 1.0),
                              0.5 * np.cos(0.5 * t)], axis=1)
    steps = Rotation.from_rotvec(rates * DT)
    attitude = [Rotation.identity()]
    for step in steps[:-1]:
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


@pytest.mark.parametrize("hard_iron", [np.zeros(3), np.array([30.0, -20.0, 10.0])])
def test_right_axes_pass_even_with_a_hard_iron(motion, hard_iron):
    rates, attitude = motion
    assert axes_fit(rates, _field(attitude, hard_iron), DT) is None


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 23), st.booleans())
def test_wrong_axes_are_found_and_undone(motion, index, left_handed):
    """Readings in any other order of the axes (right- or left-handed): the
    order proposed undoes it, up to the sign a vector's turning cannot show."""
    order = _orders()[index] * (-1.0 if left_handed else 1.0)
    if np.allclose(np.abs(order), np.eye(3)) and np.allclose(np.diag(order), order[0, 0]):
        return                                   # ±identity: the right axes
    rates, attitude = motion
    fit = axes_fit(rates, _field(attitude) @ order.T, DT)
    assert fit is not None
    declared, better, correlation = fit
    assert correlation > AXES_OTHER_ABOVE and declared < AXES_DECLARED_BELOW
    undone = better @ order
    assert np.allclose(undone, np.eye(3)) or np.allclose(undone, -np.eye(3))


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
    with pytest.raises(InvalidParameterError, match=r"opt_quat turns unlike imu_gyr_radps "
                       r"\(\d+ % .*read as \[x, y, z, w\] it would fit"):
        load_recording(path)
    np.savez(path, opt_quat=_quat(attitude * Rotation.from_euler("z", 20, degrees=True)),
             **arrays)
    with pytest.warns(UserWarning, match="opt_quat's axes are turned 20.0° from the gyro's"):
        load_recording(path)
    np.savez(path, opt_quat=quat, **arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.allclose(load_recording(path).reference_quat, quat)
