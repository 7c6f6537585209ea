"""The magnetometer's hard and soft iron from its readings alone
(sensors/magnetometer_calibration.py): recovered on simulated readings,
refused where the readings cannot determine them, applied to a declared
recording."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from conftest import npz_declaration
from dynamics.validation import InvalidParameterError
from sensors.declared import load_declared
from sensors.magnetometer_calibration import (MIN_COVERAGE, MagnetometerCalibration, coverage,
                                              fit_ellipsoid)
from sensors.recording import load_recording

FIELD_uT = 48.0
#: A soft iron as a phone's or a CubeSat's (scale factors 0.93 to 1.07, a
#: few per cent of cross-coupling), symmetric: the part an ellipsoid fit can
#: tell (a rotation after it reads the same ellipsoid).
SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.95, 0.04], [-0.02, 0.04, 1.02]])
HARD_uT = np.array([12.0, -8.0, 20.0])


def _directions(count: int, seed: int) -> np.ndarray:
    unit = np.random.default_rng(seed).normal(size=(count, 3))
    return unit / np.linalg.norm(unit, axis=1, keepdims=True)


def _readings(directions, soft=SOFT, hard=HARD_uT, noise_uT=0.0, seed=0):
    field = FIELD_uT * directions
    noise = np.random.default_rng(seed + 1).normal(scale=noise_uT, size=field.shape)
    return field @ soft.T + hard + noise


def test_a_known_hard_and_soft_iron_are_recovered_to_one_percent():
    # The target: full coverage (3000 directions, uniform), the
    # noise of a MEMS magnetometer (0.3 µT): the hard iron to 1 % of the
    # field and every soft-iron entry to 1 %. Measured: 0.007 % and 0.06 %.
    readings = _readings(_directions(3000, seed=2), noise_uT=0.3, seed=2)
    found = fit_ellipsoid(readings, field_norm=FIELD_uT)
    assert np.max(np.abs(found.hard_iron - HARD_uT)) < 0.01 * FIELD_uT
    assert np.max(np.abs(found.soft_iron - SOFT)) < 0.01
    assert found.coverage == 1.0
    # The residual is the noise over the field: 0.3 / 48 = 0.63 % (the
    # norm's noise is the noise along one axis).
    assert found.residual == pytest.approx(0.3 / FIELD_uT, rel=0.1)
    # Calibrated, every reading's norm is the field's within 4σ of the noise.
    norms = np.linalg.norm(found.apply(readings), axis=1)
    assert np.max(np.abs(norms - FIELD_uT)) < 4 * 0.3 + 0.01 * FIELD_uT


@settings(max_examples=25, deadline=None)
@given(scales=st.lists(st.floats(0.8, 1.25), min_size=3, max_size=3),
       turn=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
       hard=st.lists(st.floats(-60.0, 60.0), min_size=3, max_size=3))
def test_noiseless_readings_of_any_symmetric_soft_iron_give_it_exactly(scales, turn, hard):
    # Any symmetric positive-definite soft iron (its axes turned anywhere)
    # and any hard iron up to the field's size: on exact readings the fit is
    # exact, and without the field's norm it is the same up to the scale
    # that gives the soft iron determinant one.
    axes = Rotation.from_rotvec(turn).as_matrix()
    soft = axes @ np.diag(scales) @ axes.T
    readings = _readings(_directions(400, seed=5), soft=soft, hard=np.array(hard))
    found = fit_ellipsoid(readings, field_norm=FIELD_uT)
    assert np.allclose(found.hard_iron, hard, atol=1e-6 * FIELD_uT)
    assert np.allclose(found.soft_iron, soft, atol=1e-7)
    scaled = fit_ellipsoid(readings)
    assert np.linalg.det(scaled.soft_iron) == pytest.approx(1.0, rel=1e-9)
    assert np.allclose(scaled.soft_iron * scaled.field_norm, soft * FIELD_uT, rtol=1e-6)


def test_a_turn_about_one_axis_is_refused():
    # A phone turned flat on a table reads a ring: a family of ellipsoids
    # fit it, and the fit says so instead of choosing one.
    angle = np.linspace(0.0, 2 * np.pi, 2000)
    dip = np.radians(60.0)
    ring = np.column_stack([np.cos(dip) * np.cos(angle), np.cos(dip) * np.sin(angle),
                            np.full_like(angle, -np.sin(dip))])
    with pytest.raises(InvalidParameterError, match="turn the device through every"):
        fit_ellipsoid(_readings(ring, noise_uT=0.3), name="magnetometer")


def test_part_of_the_sphere_below_the_coverage_is_refused_with_its_share():
    directions = _directions(3000, seed=3)
    cap = directions[directions[:, 2] > 0.0]          # half the sphere
    assert coverage(cap) < MIN_COVERAGE
    with pytest.raises(InvalidParameterError, match=r"\d+% of the directions"):
        fit_ellipsoid(_readings(cap, noise_uT=0.3))


def test_a_field_that_changes_is_refused():
    # Half the readings with a magnet's 15 µT more hard iron: no one
    # ellipsoid holds them.
    directions = _directions(3000, seed=4)
    moved = np.vstack([_readings(directions[:1500], noise_uT=0.3),
                       _readings(directions[1500:], hard=HARD_uT + [15.0, 0.0, 0.0],
                                 noise_uT=0.3)])
    with pytest.raises(InvalidParameterError, match=r"a residual of [\d.]+% of the field': "
                       r"must be within 5%: the field was not constant"):
        fit_ellipsoid(moved)


def test_too_few_readings_are_refused():
    with pytest.raises(InvalidParameterError, match="at least 50"):
        fit_ellipsoid(_readings(_directions(20, seed=1)))


def test_a_reading_of_zeros_stays_no_reading():
    calibration = MagnetometerCalibration(HARD_uT, SOFT, FIELD_uT)
    readings = _readings(_directions(5, seed=1))
    readings[2] = 0.0
    applied = calibration.apply(readings)
    assert np.all(applied[2] == 0.0)
    assert np.allclose(np.linalg.norm(applied[[0, 1, 3, 4]], axis=1), FIELD_uT)


TRIAL = Path(__file__).resolve().parents[1] / "datasets" / "broad" / \
    "02_undisturbed_slow_rotation_B.npz"



@pytest.fixture(scope="module")
def distorted(tmp_path_factory):
    """Trial 02's magnetometer (a phone turned through 90 % of the
    directions) given SOFT and HARD_uT, in nT, declared."""
    recording = load_recording(TRIAL)
    folder = tmp_path_factory.mktemp("calibration")
    field = recording.magnetometer_uT
    np.savez(folder / "log.npz", t=recording.time_s, gyro=recording.gyro_radps,
             mag=(field @ SOFT.T + HARD_uT) * 1e3)
    return folder, field


def _load(folder: Path, calibration: str):
    path = folder / "log.toml"
    path.write_text(npz_declaration(magnetometer=("mag", "nT", calibration)))
    return load_declared(path).magnetometer_uT


def test_a_declared_calibrate_undoes_a_distortion_of_a_real_recording(distorted):
    folder, field = distorted
    with pytest.warns(UserWarning, match="calibrated by an ellipsoid fit: hard iron"):
        calibrated = _load(folder, "calibrate = true")
    # The distortion undone: the field's direction as the undistorted
    # readings give it, within 1.5° (the trial's own small soft iron, about
    # 2 %, is what the fit removes on top; measured: 0.78° mean).
    cosine = np.sum(calibrated * field, axis=1) / np.linalg.norm(calibrated, axis=1) / \
        np.linalg.norm(field, axis=1)
    assert np.degrees(np.mean(np.arccos(np.clip(cosine, -1, 1)))) < 1.5
    # Uncalibrated, the distortion's directions are off by degrees (29°).
    raw = _load(folder, "")
    raw_cosine = np.sum(raw * field, axis=1) / np.linalg.norm(raw, axis=1) / \
        np.linalg.norm(field, axis=1)
    assert np.degrees(np.mean(np.arccos(np.clip(raw_cosine, -1, 1)))) > 5.0


def test_a_declared_hard_and_soft_iron_are_applied_exactly(distorted):
    folder, field = distorted
    calibrated = _load(folder, f"hard_iron = {(HARD_uT * 1e3).tolist()}\n"
                       f"soft_iron = {SOFT.tolist()}")
    assert np.allclose(calibrated, field, atol=1e-9)


@pytest.mark.parametrize("calibration, message", [
    ("calibrate = 1", "calibrate = 1: must be true or false"),
    ("calibrate = true\nhard_iron = [1, 2, 3]", "hard_iron = \\[1, 2, 3\\]: is declared beside"),
    ("soft_iron = [[1, 0], [0, 1]]", "soft_iron = .*: must be 3 × 3 finite numbers"),
    ("soft_iron = [[1, 0, 0], [0, 1, 0], [0, 0, 0]]", "soft_iron = .*: must be invertible"),
    ("hard_iron = [1, 2]", "hard_iron = \\[1, 2\\]: must be 3 finite numbers"),
])
def test_a_malformed_calibration_is_one_line(distorted, calibration, message):
    folder, _ = distorted
    with pytest.raises(InvalidParameterError, match=f"log.toml: recording.magnetometer.*{message}"):
        _load(folder, calibration)


def _orbit_readings(seed: int, count: int = 3000, sigma_nT: float = 200.0):
    """A CubeSat's magnetometer over an orbit's field (20 to 45 µT, turning
    twice an orbit) while the body turns at 1.2 °/s, with a 950 nT hard iron
    (the issue's): the readings and the field's norm at each, nT."""
    rng = np.random.default_rng(seed)
    t = np.arange(count, dtype=float)
    angle = 4 * np.pi * t / 5676.0
    field = np.column_stack([30e3 * np.cos(angle), 30e3 * np.sin(angle),
                             15e3 + 10e3 * np.sin(angle / 2)])
    body = Rotation.from_rotvec(np.outer(t, [0.012, -0.008, 0.015])).inv().apply(field)
    readings = body + ORBIT_HARD_nT + rng.normal(scale=sigma_nT, size=body.shape)
    return readings, np.linalg.norm(field, axis=1)


ORBIT_HARD_nT = np.array([950.0, -400.0, 300.0])


def test_twostep_estimates_a_hard_iron_consistently_and_fails_when_mistuned():
    # TWOSTEP's covariance is the inverse of its Fisher information: over 50
    # seeds the estimate errors' mean NEES is χ²(150)/50 distributed; its
    # two-sided 99 % band is [2.18, 3.97] (scipy.stats.chi2). Measured: 3.00
    # (told the true noise), 48.2 (told a quarter of it).
    from scipy.stats import chi2
    from sensors.magnetometer_calibration import twostep
    seeds = 50
    band = chi2.ppf([0.005, 0.995], 3 * seeds) / seeds

    def anees(told_sigma):
        values = []
        for seed in range(seeds):
            bias, covariance = twostep(*_orbit_readings(seed), told_sigma)
            error = bias - ORBIT_HARD_nT
            values.append(error @ np.linalg.solve(covariance, error))
        return float(np.mean(values))
    assert band[0] < anees(200.0) < band[1]
    # Told a noise four times too small, it claims a covariance sixteen
    # times too small: far above the band.
    assert anees(50.0) > 4 * band[1]


def test_a_sensor_mounted_on_other_axes_is_read_in_the_devices(tmp_path):
    # An MPU-9250's magnetometer reads (y, x, -z) of the gyro's axes: with
    # axes = ["y", "x", "-z"] the declared recording is the device's field.
    recording = load_recording(TRIAL)
    field = recording.magnetometer_uT
    sensor = np.column_stack([field[:, 1], field[:, 0], -field[:, 2]])
    np.savez(tmp_path / "log.npz", t=recording.time_s, gyro=recording.gyro_radps, mag=sensor)
    path = tmp_path / "log.toml"
    path.write_text(npz_declaration(magnetometer=("mag", "uT", 'axes = ["y", "x", "-z"]')))
    assert np.array_equal(load_declared(path).magnetometer_uT, field)
    path.write_text(npz_declaration(magnetometer=("mag", "uT", 'axes = ["y", "y", "-z"]')))
    with pytest.raises(InvalidParameterError, match=r"log.toml: recording.magnetometer.axes = "
                       r"\['y', 'y', '-z'\]: must be three of"):
        load_declared(path)


def test_the_fit_is_the_same_in_any_unit_and_refuses_constant_readings():
    # The fit's checks are free of the readings' unit: the same readings in
    # µT, nT and gauss give the same calibration, scaled.
    readings = _readings(_directions(2000, seed=6), noise_uT=0.3, seed=6)
    in_uT = fit_ellipsoid(readings)
    for scale in (1e3, 1e-2):
        found = fit_ellipsoid(readings * scale)
        assert np.allclose(found.hard_iron, in_uT.hard_iron * scale, rtol=1e-6)
        assert np.allclose(found.soft_iron, in_uT.soft_iron, atol=1e-8)
    with pytest.raises(InvalidParameterError, match="are all the same"):
        fit_ellipsoid(np.tile([20.0, 5.0, 40.0], (200, 1)))
    with pytest.raises(InvalidParameterError, match="field_norm = 'x': must be a positive"):
        fit_ellipsoid(readings, field_norm="x")
