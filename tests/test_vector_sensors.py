"""Vector sensors: their noise against their σ (χ² bounds), their visibility
rules, and the scenario's refusals."""
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from benchmarks import Scenario
from benchmarks.simulation import scenario_references, simulate_sensors, simulate_truth
from dynamics.environment import References
from dynamics.quaternion import rotation_matrix
from dynamics.validation import InvalidParameterError
from sensors.accelerometer import GRAVITY_REACTION_ENU_MPS2, Accelerometer
from sensors.magnetometer import Magnetometer
from sensors.sun_sensor import CoarseSunSensors, FineSunSensor
from sensors.vector import to_body
from tests.conftest import random_unit_quaternions

ISS_TLE = ("1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991",
           "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482")
CUBESAT = Path(__file__).resolve().parents[1] / "scenarios" / "cubesat.toml"
#: Two-sided probability of each χ² check: a correct sensor fails one in 1000.
LEVEL = 0.999


def sunlit(sun, illumination):
    """References of a Sun direction and illumination alone."""
    return References(np.zeros_like(sun), sun_unit=sun, illumination=illumination)


def chi2_bounds(dof: int) -> tuple[float, float]:
    return tuple(chi2.ppf([(1 - LEVEL) / 2, (1 + LEVEL) / 2], dof))


def test_magnetometer_noise_is_its_sigma_per_axis(rng):
    # Σ (residual/σ)² over N readings of 3 axes is χ²(3N).
    n = 4000
    q = random_unit_quaternions(rng, n)
    field = rng.normal(0, 30000, (n, 3))
    sensor = Magnetometer(150.0, 1.0, 1.0)
    readings = sensor.measure(q, References(field), np.random.default_rng(1))
    residual = readings.body - to_body(q, field)
    low, high = chi2_bounds(3 * n)
    assert low < np.sum((residual / 150.0) ** 2) < high
    assert readings.dof == 3 and readings.unit == "nT"
    assert np.all(readings.variance == 150.0 ** 2)


def test_magnetometer_applies_its_soft_and_hard_iron():
    q = np.tile([1.0, 0, 0, 0], (3, 1))
    field = np.array([[1000.0, 0, 0], [0, 1000.0, 0], [0, 0, 1000.0]])
    soft = np.array([[1.1, 0.02, 0], [0, 0.95, 0], [0, 0, 1.0]])
    sensor = Magnetometer(1e-9, 1.0, 1.0, bias_nT=(50.0, -20.0, 10.0), soft_iron=soft)
    body = sensor.measure(q, References(field), np.random.default_rng(0)).body
    assert np.allclose(body, field @ soft.T + [50.0, -20.0, 10.0], atol=1e-6)


def test_fine_sun_sensor_error_lies_across_the_sun_with_its_sigma(rng):
    # The angle between the reading and the truth, over σ, is χ(2): Σ (θ/σ)² ~ χ²(2N).
    n = 4000
    q = random_unit_quaternions(rng, n)
    sun = np.tile([1.0, 0.0, 0.0], (n, 1))
    sensor = FineSunSensor(0.1, 1.0, 1.0, fov_deg=90.0, boresight=(1, 0, 0))
    readings = sensor.measure(q, sunlit(sun, np.ones(n)), np.random.default_rng(2))
    truth = to_body(q, sun)
    seen = readings.available
    assert 0.4 < seen.mean() < 0.6                 # a hemisphere of attitudes
    body = readings.body[seen]
    assert np.allclose(np.linalg.norm(body, axis=1), 1.0, atol=1e-12)
    angle = np.arccos(np.clip(np.sum(body * truth[seen], axis=1), -1, 1))
    low, high = chi2_bounds(2 * seen.sum())
    assert low < np.sum((angle / math.radians(0.1)) ** 2) < high
    assert readings.dof == 2


def test_fine_sun_sensor_reads_only_in_its_field_of_view_and_in_sunlight(rng):
    n = 2000
    q = random_unit_quaternions(rng, n)
    sun = np.tile([0.0, 0.0, 1.0], (n, 1))
    lit = np.where(np.arange(n) < n // 2, 1.0, 0.0)
    sensor = FineSunSensor(0.1, 1.0, 1.0, fov_deg=30.0)
    readings = sensor.measure(q, sunlit(sun, lit), np.random.default_rng(3))
    cosine = to_body(q, sun) @ np.array([0.0, 0.0, 1.0])
    assert np.array_equal(readings.available, (cosine >= math.cos(math.radians(30))) & (lit == 1))
    assert not readings.available[n // 2:].any()


def test_coarse_sun_sensors_give_an_unbiased_vector_with_their_variance(rng):
    # The cube's three lit faces: the least-squares vector's error is σ_c per
    # axis, Σ |error|² / σ_c² ~ χ²(3N) (faces near the terminator, lit or not
    # by the noise, bias it by O(σ_c²): below this test's resolution).
    n = 3000
    q = random_unit_quaternions(rng, n)
    sun = np.tile([0.6, 0.0, 0.8], (n, 1))
    sensor = CoarseSunSensors(0.01, 1.0, 1.0)
    readings = sensor.measure(q, sunlit(sun, np.ones(n)), np.random.default_rng(4))
    seen = readings.available
    assert seen.mean() > 0.95
    error = readings.body[seen] - to_body(q[seen], sun[seen])
    low, high = chi2_bounds(3 * seen.sum())
    assert low < np.sum(error ** 2 / readings.variance[seen][:, None]) < high
    # No reading in eclipse.
    dark = sensor.measure(q, sunlit(sun, np.zeros(n)), np.random.default_rng(4))
    assert not dark.available.any()


@pytest.mark.parametrize("sun", [[1.0, 0.0, 0.0], [0.6, 0.8, 0.0]])
def test_coarse_sun_sensors_read_with_the_sun_on_a_face_normal_or_in_a_face_plane(sun):
    # A sun-pointing CubeSat: one or two faces lit, the others reading their
    # noise. The brightest faces that span space still give every reading;
    # choosing the brighter of two dark faces biases that axis by about
    # 0.56 σ_c (E max of two normals), so the mean squared error per axis is
    # up to 1 + 0.32: bounded here by 1.5 σ_c² (a wrong face would give ~60).
    n = 500
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    sun = np.tile(sun, (n, 1))
    readings = CoarseSunSensors(0.01, 1.0, 1.0).measure(q, sunlit(sun, np.ones(n)),
                                                        np.random.default_rng(6))
    assert readings.available.all()
    error = readings.body - sun
    assert 0.7 < np.mean(error ** 2 / readings.variance[:, None]) < 1.5


def test_accelerometer_reads_gravity_s_reaction_with_its_sigma(rng):
    n = 3000
    q = random_unit_quaternions(rng, n)
    sensor = Accelerometer(0.02, 1.0, 1.0)
    readings = sensor.measure(q, None, np.random.default_rng(5))
    residual = readings.body - to_body(q, np.tile(GRAVITY_REACTION_ENU_MPS2, (n, 1)))
    low, high = chi2_bounds(3 * n)
    assert low < np.sum((residual / 0.02) ** 2) < high
    # Level and at rest, it reads +g up.
    level = sensor.measure(np.tile([1.0, 0, 0, 0], (1, 1)), None,
                           np.random.default_rng(5)).body[0]
    assert level[2] == pytest.approx(9.80665, abs=0.1)


def test_a_sensor_reads_every_interval_on_the_gyro_grid():
    sensor = Magnetometer(100.0, 0.5, 0.1)
    readings = sensor.measure(np.tile([1.0, 0, 0, 0], (21, 1)), References(np.ones((21, 3))),
                              np.random.default_rng(0))
    assert np.array_equal(np.flatnonzero(readings.available), np.arange(0, 21, 5))


def test_no_sun_reading_in_eclipse_on_the_cubesat_scenario():
    scenario = Scenario.from_toml(CUBESAT).replace(tstop=3000.0)
    sensors = simulate_sensors(scenario, simulate_truth(scenario), seed=0)
    eclipse = sensors.references.eclipse
    assert eclipse.any() and not eclipse.all()
    for readings in sensors.vectors:
        if readings.sensor in ("sun_sensor", "coarse_sun_sensors"):
            assert not readings.available[eclipse].any()
            assert readings.available[~eclipse].any()
        else:
            assert readings.available.all()


def test_vector_sensors_draw_from_their_own_streams():
    # Adding the magnetometer changes no gyro draw (its stream is the 4th child).
    base = Scenario.from_toml(CUBESAT).replace(tstop=100.0)
    without = base.replace(magnetometer_interval_s=None)
    a = simulate_sensors(base, simulate_truth(base), seed=7)
    b = simulate_sensors(without, simulate_truth(without), seed=7)
    assert np.array_equal(a.omega_meas_radps, b.omega_meas_radps)
    assert [r.sensor for r in a.vectors] == ["magnetometer", "sun_sensor", "coarse_sun_sensors"]


def test_references_are_cached_and_in_the_reference_frame():
    scenario = Scenario.from_toml(CUBESAT).replace(tstop=200.0)
    first = scenario_references(scenario)
    assert scenario_references(scenario) is first
    assert np.allclose(np.linalg.norm(first.sun_unit, axis=1), 1.0)
    strength = np.linalg.norm(first.magnetic_field_nT, axis=1)
    assert np.all((strength > 15000) & (strength < 60000))       # LEO's field


@pytest.mark.parametrize("changes, name, rule", [
    ({"magnetometer_interval_s": 1.0}, "magnetometer.interval_s", "needs an [orbit] or a [site]"),
    ({"orbit_altitude_km": 500.0, "accelerometer_interval_s": 1.0}, "accelerometer.interval_s",
     "in orbit it reads no gravity"),
    ({"site_latitude_deg": 45.0, "sun_sensor_interval_s": 1.0}, "sun_sensor.interval_s",
     "needs an [orbit]"),
    ({"orbit_altitude_km": 500.0, "magnetometer_interval_s": 0.015}, "magnetometer.interval_s",
     "whole multiple of dt"),
    ({"orbit_altitude_km": 500.0, "magnetometer_interval_s": 1.0, "magnetometer_sigma_nT": 0.0},
     "magnetometer.sigma_nT", "> 0"),
    ({"orbit_altitude_km": 500.0, "sun_sensor_interval_s": 1.0, "sun_sensor_fov_deg": 120.0},
     "sun_sensor.fov_deg", "at most 90"),
    ({"orbit_altitude_km": 500.0, "coarse_sun_interval_s": 1.0,
      "coarse_sun_normals": [[1, 0, 0], [0, 1, 0], [1, 1, 0]]}, "coarse_sun_sensors.normals",
     "span three dimensions"),
    ({"star_tracker_model": "none"}, "star_tracker.model", "leaves no attitude sensor"),
    ({"orbit_altitude_km": 500.0, "site_latitude_deg": 10.0}, "site.latitude_deg",
     "in orbit or on the ground"),
    ({"epoch": "yesterday"}, "environment.epoch", "ISO 8601"),
    ({"magnetic_field_model": "wmm"}, "environment.magnetic_field_model", "igrf"),
    ({"orbit_tle": 5}, "orbit.tle", "two-line element set"),
    ({"orbit_tle": ISS_TLE, "epoch": "2026-01-01T00:00:00"}, "environment.epoch",
     "days from the element set's epoch"),
    ({"site_latitude_deg": 10.0, "site_longitude_deg": 400.0}, "site.longitude_deg",
     "within -360 and 360"),
    ({"site_latitude_deg": 10.0, "site_altitude_km": 1e6}, "site.altitude_km", "within -1"),
    ({"site_latitude_deg": 10.0, "magnetic_field_model": "dipole"},
     "environment.magnetic_field_model", "a [site] on the ground takes IGRF"),
    ({"orbit_altitude_km": 500.0, "magnetometer_interval_s": 1.0,
      "magnetometer_soft_iron": [[1, 0], [0, 1]]}, "magnetometer.soft_iron", "3x3"),
])
def test_bad_vector_sensor_settings_are_refused_by_name(changes, name, rule):
    with pytest.raises(InvalidParameterError, match=re.escape(rule)) as raised:
        Scenario(**changes)
    assert raised.value.name == name


def test_the_cubesat_file_reads_in_its_sections():
    scenario = Scenario.from_toml(CUBESAT)
    assert scenario.star_tracker_model == "none"
    assert scenario.orbit_altitude_km == 500.0 and scenario.magnetometer_sigma_nT == 200.0
    assert [s.name for s in scenario.build_vector_sensors()] == [
        "magnetometer", "sun_sensor", "coarse_sun_sensors"]
    assert not scenario.is_workshop_sensors
    assert rotation_matrix(scenario.initial_attitude_quat).shape == (3, 3)


def test_a_tle_scenario_starts_at_the_elements_epoch_and_reads_a_pasted_text():
    as_list = Scenario(star_tracker_model="none", orbit_tle=ISS_TLE, magnetometer_interval_s=0.2,
                       tstop=1.0)
    as_text = as_list.replace(orbit_tle="\n".join(ISS_TLE))
    assert as_text.orbit_tle == as_list.orbit_tle
    moment = as_list.epoch_moment
    assert (moment.year, moment.month, moment.day, moment.hour) == (2019, 12, 9, 16)
