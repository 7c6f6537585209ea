"""What a scenario describes, built: its sensors, its orbit and its time zero.

Each function reads a :class:`~benchmarks.scenario.Scenario` (never changes
it) and builds what its settings describe; the scenario's own methods are
these (``scenario.build_gyro()`` is :func:`gyro`). The sensor classes check
their settings themselves, so building a sensor is also how a scenario checks
them (:func:`benchmarks.scenario.checks.check_sensors`).
"""
from __future__ import annotations

from dynamics.orbit import DEFAULT_EPOCH, TLEOrbit, epoch_datetime, make_orbit
from dynamics.validation import InvalidParameterError, finite_number
from sensors.accelerometer import Accelerometer
from sensors.gyro import Gyro
from sensors.magnetometer import Magnetometer
from sensors.star_tracker import (NoStarTracker, RotationStarTracker, StarTracker,
                                  steps_between_readings)
from sensors.sun_sensor import CoarseSunSensors, FineSunSensor


def gyro(scenario) -> Gyro:
    """The gyro a scenario describes."""
    return Gyro(scenario.gyro_noise, scenario.dt,
                bias_random_walk=scenario.gyro_bias_random_walk,
                initial_bias_radps=scenario.gyro_initial_bias_radps,
                scale_misalignment=scenario.gyro_scale_misalignment,
                sampling=scenario.gyro_sampling,
                bias_instability_radps=scenario.gyro_bias_instability_radps,
                bias_correlation_time_s=scenario.gyro_bias_correlation_time_s)


def star_tracker(scenario) -> StarTracker | RotationStarTracker | NoStarTracker:
    """The star tracker a scenario describes (its ``star_tracker_model``)."""
    if scenario.star_tracker_model == "workshop":
        return StarTracker(scenario.star_tracker_noise, scenario.time_between_measurements,
                           scenario.dt)
    if scenario.star_tracker_model == "none":
        return NoStarTracker(scenario.time_between_measurements, scenario.dt)
    return rotation_star_tracker(scenario)


def rotation_star_tracker(scenario) -> RotationStarTracker:
    """The rotation-noise star tracker of a scenario's settings, whichever
    model the scenario chose."""
    return RotationStarTracker(
        scenario.star_tracker_sigma_arcsec, scenario.time_between_measurements, scenario.dt,
        dropout_probability=scenario.star_tracker_dropout_probability,
        outages_s=scenario.star_tracker_outages_s, sign=scenario.star_tracker_sign,
        sensor_to_body_quat=scenario.star_tracker_to_body_quat)


def vector_sensors(scenario) -> list:
    """The vector sensors a scenario has, in a fixed order (magnetometer,
    fine sun sensor, coarse sun sensors, accelerometer)."""
    sensors, dt = [], scenario.dt
    if scenario.magnetometer_interval_s is not None:
        sensors.append(Magnetometer(scenario.magnetometer_sigma_nT,
                                    _interval(scenario, "magnetometer"), dt,
                                    bias_nT=scenario.magnetometer_bias_nT,
                                    soft_iron=scenario.magnetometer_soft_iron))
    if scenario.sun_sensor_interval_s is not None:
        sensors.append(FineSunSensor(scenario.sun_sensor_sigma_deg,
                                     _interval(scenario, "sun_sensor"), dt,
                                     fov_deg=scenario.sun_sensor_fov_deg,
                                     boresight=scenario.sun_sensor_boresight))
    if scenario.coarse_sun_interval_s is not None:
        sensors.append(CoarseSunSensors(scenario.coarse_sun_sigma,
                                        _interval(scenario, "coarse_sun"), dt,
                                        normals=scenario.coarse_sun_normals))
    if scenario.accelerometer_interval_s is not None:
        sensors.append(Accelerometer(scenario.accelerometer_sigma_mps2,
                                     _interval(scenario, "accelerometer"), dt,
                                     bias_mps2=scenario.accelerometer_bias_mps2))
    return sensors


def _interval(scenario, prefix: str) -> float:
    """A vector sensor's interval: a whole multiple of ``dt`` (its section named)."""
    section = {"coarse_sun": "coarse_sun_sensors"}.get(prefix, prefix)
    name = f"{section}.interval_s"
    value = finite_number(name, getattr(scenario, f"{prefix}_interval_s"),
                          strictly_positive=True)
    try:
        steps_between_readings(value, scenario.dt)
    except InvalidParameterError as err:
        raise InvalidParameterError(name, value, err.rule) from None
    return value


def orbit(scenario):
    """The :class:`~dynamics.orbit.CircularOrbit` or
    :class:`~dynamics.orbit.TLEOrbit` a scenario describes, or None."""
    return make_orbit(**orbit_settings(scenario))


def orbit_settings(scenario) -> dict:
    """The keywords of :func:`dynamics.orbit.make_orbit` (hashable values)."""
    return {"epoch": epoch_moment(scenario),
            "tle": tuple(scenario.orbit_tle), "altitude_km": scenario.orbit_altitude_km,
            "inclination_deg": scenario.orbit_inclination_deg,
            "raan_deg": scenario.orbit_raan_deg,
            "argument_of_latitude_deg": scenario.orbit_argument_of_latitude_deg}


def epoch_moment(scenario):
    """Time zero as a UTC datetime: the given epoch, or the element set's,
    or :data:`dynamics.orbit.DEFAULT_EPOCH`."""
    if scenario.epoch is not None:
        return epoch_datetime("environment.epoch", scenario.epoch)
    if scenario.orbit_tle:
        return TLEOrbit(scenario.orbit_tle).element_epoch
    return epoch_datetime("environment.epoch", DEFAULT_EPOCH)
