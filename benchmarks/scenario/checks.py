"""The checks a scenario makes of itself, in the order it makes them.

A :class:`~benchmarks.scenario.Scenario` checks itself on construction
(its ``__post_init__``): one value at a time, each stored as checked (a list
becomes an array, an interval a float), the sensors built once so that their
classes check their own settings (:mod:`benchmarks.scenario.builders`); then
the checks beyond one value: limits that keep a run meaningful and finite (its
length, the body rate, the sensors' noise), the σ the sensors square, a
ground site's coordinates, and where each sensor is: the orbit, the site and
the vector sensors must agree, each sensor where it can read, and some
attitude sensor present. Last, the estimators' own fields left None are
derived from the sensors, and each estimator's ``[estimators.NAME]`` options
tried on the scenario. Each check raises
:class:`~dynamics.validation.InvalidParameterError` naming the setting (as
the file's ``section.key`` where that is clearer), the value and the rule;
a sensor idle for the whole run is a warning, not a refusal.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from benchmarks.scenario import builders
from benchmarks.scenario.settings import estimator_class, plain_value, toml_key
from dynamics.environment import FIELD_MODELS, SHADOW_MODELS, igrf_date
from dynamics.orbit import TLEOrbit, epoch_datetime, tle_lines
from dynamics.validation import (InvalidParameterError, axis_standard_deviations,
                                 covariance_matrix, finite_number, finite_vector, inertia_tensor,
                                 nonzero_quaternion, one_of, process_exponent,
                                 standard_deviation)
from estimators import ESTIMATORS
from sensors.star_tracker import outage_windows, reading_interval

#: The star tracker models: additive quaternion noise of power
#: ``star_tracker_noise`` (the workshop's), a small error rotation of
#: ``star_tracker_sigma_arcsec`` (:mod:`sensors.star_tracker`), or no star
#: tracker (vector sensors only).
STAR_TRACKER_MODELS = ("workshop", "rotation", "none")
#: Body rates above this (rad/s, about 1600 revolutions a minute) are refused:
#: no attitude sensor suite is built for them, and the truth's integrator
#: would need billions of steps.
MAX_RATE_RADPS = 100.0
#: The largest gyro noise σ per sample, rad/s: readings then stay far inside
#: the ±1000 rad/s an estimator accepts (dynamics.validation.MAX_MEASURED_RATE_RADPS).
MAX_GYRO_NOISE_RADPS = 10.0
#: The largest star tracker noise σ per quaternion component (the workshop
#: model): a unit quaternion's components are at most 1.
MAX_STAR_NOISE = 10.0
#: Longest time grid, in steps. The engine's memory no longer grows with the
#: run, but its time does: at about ten million run-steps a second, one run
#: of this many steps is a quarter of an hour of the whole machine.
MAX_STEPS = 10**10
#: An element set is propagated over the run, when the scenario is checked,
#: at its every step or at this many steps spread over it (SGP4's failures,
#: a decay, persist once they start).
ORBIT_CHECK_STEPS = 10_001


def _store(scenario, name: str, value) -> None:
    """Keep ``value`` as checked: a scenario is frozen, and checks itself as it is made."""
    object.__setattr__(scenario, name, value)


def check_run_and_truth(scenario) -> None:
    """The time grid, and the truth's initial state."""
    _store(scenario, "dt", finite_number("dt", scenario.dt, strictly_positive=True))
    _store(scenario, "tstop", finite_number("tstop", scenario.tstop, strictly_positive=True))
    check_run_length(scenario.tstop, scenario.dt)
    _store(scenario, "inertia_tensor_kg_m2", inertia_tensor("inertia_tensor_kg_m2",
                                                            scenario.inertia_tensor_kg_m2))
    _store(scenario, "initial_attitude_quat", nonzero_quaternion(
        "initial_attitude_quat", scenario.initial_attitude_quat))
    _store(scenario, "initial_rate_radps", finite_vector("initial_rate_radps",
                                                         scenario.initial_rate_radps, 3))
    check_body_rate(scenario.initial_rate_radps)


def check_sensors(scenario) -> None:
    """The gyro and the star tracker: their noise, interval and model here,
    the rest normalised by their own classes."""
    def store(name, value):
        _store(scenario, name, value)
    store("gyro_noise", finite_number("gyro_noise", scenario.gyro_noise, minimum=0.0))
    check_gyro_noise(scenario.gyro_noise, scenario.dt)
    store("star_tracker_noise", finite_number("star_tracker_noise", scenario.star_tracker_noise,
                                              minimum=0.0))
    check_star_tracker_noise(scenario.star_tracker_noise, scenario.dt)
    store("time_between_measurements", reading_interval(scenario.time_between_measurements,
                                                        scenario.dt))
    store("initial_state", nonzero_quaternion("initial_state", scenario.initial_state))
    one_of("star_tracker_model", scenario.star_tracker_model, STAR_TRACKER_MODELS)
    store("star_tracker_outages_s", outage_windows("star_tracker_outages_s",
                                                   scenario.star_tracker_outages_s))
    check_standard_deviations(scenario)
    # The sensor classes validate (and normalise) their own settings.
    gyro, star_tracker = builders.gyro(scenario), builders.star_tracker(scenario)
    store("gyro_bias_random_walk", gyro.bias_random_walk)
    store("gyro_initial_bias_radps", gyro.initial_bias_radps)
    store("gyro_scale_misalignment", np.zeros((3, 3)) if gyro.scale_misalignment is None
          else gyro.scale_misalignment)
    # The rotation tracker's settings are checked whichever model is chosen:
    # a file that switches models later should not hide a bad value.
    rotation = star_tracker if star_tracker.model == "rotation" else \
        builders.rotation_star_tracker(scenario)
    store("star_tracker_sigma_arcsec", rotation.sigma_arcsec)
    store("star_tracker_dropout_probability", rotation.dropout_probability)
    store("star_tracker_to_body_quat", rotation.sensor_to_body_quat)


def check_environment(scenario) -> None:
    """The epoch and the environment's models; then the orbit, the site and
    the vector sensors (:func:`check_places`)."""
    if scenario.epoch is not None:
        _store(scenario, "epoch", epoch_datetime("environment.epoch",
                                                 scenario.epoch).isoformat())
    one_of("environment.magnetic_field_model", scenario.magnetic_field_model, FIELD_MODELS)
    one_of("environment.shadow_model", scenario.shadow_model, SHADOW_MODELS)
    _store(scenario, "orbit_tle", tle_lines("orbit.tle", scenario.orbit_tle))
    check_places(scenario)


def derive_estimator_fields(scenario) -> None:
    """Fill the estimators' own fields left None with what each estimator
    derives from the scenario's sensors (its ``derived_fields``), and note
    which they were (``scenario.derived_fields``, kept by ``replace`` so that
    a changed sensor derives them anew)."""
    derived = set()
    for cls in dict.fromkeys(ESTIMATORS.values()):
        missing = [cls.scenario_defaults[keyword] for keyword in cls.owned_fields
                   if getattr(scenario, cls.scenario_defaults[keyword]) is None]
        if not missing:
            continue
        values = cls.derived_fields(scenario)
        for name in missing:
            _store(scenario, name, values[name])
            derived.add(name)
    _store(scenario, "derived_fields", frozenset(derived))


def check_estimator_fields(scenario) -> None:
    """The estimators' own fields, derived or given, and their options
    (:func:`checked_options`)."""
    _store(scenario, "pc_exponent", process_exponent("pc_exponent", scenario.pc_exponent))
    _store(scenario, "measurement_covariance", covariance_matrix(
        "measurement_covariance", scenario.measurement_covariance))
    _store(scenario, "initial_covariance", finite_number(
        "initial_covariance", scenario.initial_covariance, strictly_positive=True))
    _store(scenario, "estimator_options", checked_options(scenario, scenario.estimator_options))


def check_run_length(tstop: float, dt: float) -> None:
    """At least one step (``tstop >= dt``) and at most :data:`MAX_STEPS`."""
    if tstop < dt:
        raise InvalidParameterError("tstop", tstop, f"must be >= dt = {dt:g}")
    if tstop / dt >= MAX_STEPS:
        steps = tstop / dt
        raise InvalidParameterError(
            "tstop", tstop, (f"makes {steps:,.0f}" if steps < 1e15 else
                             f"makes {steps:.3g}") + f" steps of dt = {dt:g}; at "
            f"most {MAX_STEPS:,} steps (tstop = {MAX_STEPS * dt:,.0f} s)")


def check_body_rate(rate_radps: np.ndarray) -> None:
    """Each component of the initial body rate within :data:`MAX_RATE_RADPS`."""
    if np.abs(rate_radps).max() > MAX_RATE_RADPS:
        raise InvalidParameterError("initial_rate_radps", rate_radps,
                                    f"each component must be within ±{MAX_RATE_RADPS:g} rad/s "
                                    "(a spacecraft, not a centrifuge)")


def check_gyro_noise(noise_power: float, dt: float) -> None:
    """The gyro's per-sample noise σ = √(p/dt) within :data:`MAX_GYRO_NOISE_RADPS`."""
    if noise_power / dt > MAX_GYRO_NOISE_RADPS ** 2:
        raise InvalidParameterError(
            "gyro_noise", noise_power, f"makes the reading noise √(p/dt) = "
            f"{math.sqrt(noise_power / dt):.3g} rad/s per sample; at most "
            f"{MAX_GYRO_NOISE_RADPS:g} rad/s (gyro_noise <= "
            f"{MAX_GYRO_NOISE_RADPS ** 2 * dt:g} with dt = {dt:g})")


def check_star_tracker_noise(noise_power: float, dt: float) -> None:
    """The workshop star tracker's per-sample noise σ = √(p/dt) within
    :data:`MAX_STAR_NOISE`."""
    if noise_power / dt > MAX_STAR_NOISE ** 2:
        raise InvalidParameterError(
            "star_tracker_noise", noise_power, f"makes the reading noise "
            f"√(p/dt) = {math.sqrt(noise_power / dt):.3g} per quaternion "
            f"component; at most {MAX_STAR_NOISE:g}, beyond which a reading is noise alone "
            f"(star_tracker_noise <= {MAX_STAR_NOISE ** 2 * dt:g} with dt = "
            f"{dt:g})")


def check_standard_deviations(scenario) -> None:
    """The σ the sensors square into variances: refused here while the
    square would overflow (the sensors check the rest)."""
    standard_deviation("gyro_bias_random_walk", scenario.gyro_bias_random_walk)
    standard_deviation("gyro_bias_instability_radps", scenario.gyro_bias_instability_radps)
    if np.ndim(scenario.star_tracker_sigma_arcsec) == 1:     # one σ per sensor axis
        axis_standard_deviations("star_tracker_sigma_arcsec",
                                 scenario.star_tracker_sigma_arcsec)


def site_coordinates(latitude_deg, longitude_deg, altitude_km) -> tuple:
    """A ground site's ``(latitude_deg, longitude_deg, altitude_km)``, each
    finite and within its range (the file's ``site.KEY`` named)."""
    values = []
    for name, value, low, high in (("latitude_deg", latitude_deg, -90.0, 90.0),
                                   ("longitude_deg", longitude_deg, -360.0, 360.0),
                                   ("altitude_km", altitude_km, -1.0, 100.0)):
        number = finite_number(f"site.{name}", value)
        if not low <= number <= high:
            raise InvalidParameterError(f"site.{name}", value,
                                        f"must be within {low:g} and {high:g}")
        values.append(number)
    return tuple(values)


def check_places(scenario) -> None:
    """The orbit and the site, each built once (its class checks its
    settings) and not both; an element set propagated over the run; and
    each sensor where it can read (:func:`check_sensor_places`)."""
    if scenario.orbit_tle and scenario.orbit_altitude_km is not None:
        raise InvalidParameterError("orbit.altitude_km", scenario.orbit_altitude_km,
                                    "cannot be given with orbit.tle: the orbit is a circular "
                                    "one (altitude_km) or an element set's (tle), not both")
    orbit, site = scenario.build_orbit(), scenario.site
    if orbit is not None and site is not None:
        raise InvalidParameterError("site.latitude_deg", scenario.site_latitude_deg,
                                    "cannot be set with an [orbit]: a scenario is in orbit "
                                    "or on the ground")
    if site is not None and scenario.magnetic_field_model == "dipole":
        raise InvalidParameterError("environment.magnetic_field_model", "dipole",
                                    "is for orbits; a [site] on the ground takes IGRF")
    if isinstance(orbit, TLEOrbit):
        # Here, not steps into a run: show-config must refuse a decay too.
        n_steps = scenario.n_steps
        steps = np.arange(n_steps) if n_steps <= ORBIT_CHECK_STEPS else \
            np.unique(np.linspace(0, n_steps - 1, ORBIT_CHECK_STEPS).round())
        orbit.check_propagation(steps * scenario.dt)
    check_sensor_places(scenario, orbit, site)
    if scenario.has_vector_sensors and (orbit is not None or site is not None):
        igrf_date(scenario.epoch_moment)        # warns if the field is held at IGRF's end


def check_sensor_places(scenario, orbit, site) -> None:
    """Each vector sensor where it can read; and some attitude sensor."""
    sensors = scenario.build_vector_sensors()
    for sensor in sensors:
        where = {"accelerometer": site, "sun_sensor": orbit,
                 "coarse_sun_sensors": orbit}.get(sensor.name, orbit or site)
        if where is None:
            needs = ("a [site] (on the ground; in orbit it reads no gravity)"
                     if sensor.name == "accelerometer" else "an [orbit] (for the Sun)"
                     if sensor.name != "magnetometer" else "an [orbit] or a [site]")
            raise InvalidParameterError(f"{sensor.name}.interval_s", sensor.interval_s,
                                        f"needs {needs}")
    if scenario.star_tracker_model == "none" and not sensors:
        raise InvalidParameterError("star_tracker.model", "none", "leaves no attitude "
                                    "sensor: add a vector sensor ([magnetometer], "
                                    "[sun_sensor], …) or choose a star tracker model")


def warn_of_idle_sensors(scenario) -> None:
    """A sensor whose interval is longer than the run reads once, at t = 0.
    Said, not refused: shortening a run (``--tstop``) for a quick look
    is ordinary, and the run is well defined; but it is rarely meant.
    The warning points at this function's caller."""
    intervals = [(f"{sensor.name}.interval_s", sensor.interval_s)
                 for sensor in scenario.build_vector_sensors()]
    if scenario.star_tracker_model != "none":
        intervals.insert(0, ("star_tracker.interval_s", scenario.time_between_measurements))
    for name, interval in intervals:
        if interval > scenario.tstop:
            warnings.warn(f"{name} = {interval:g} s is longer than the run (tstop = "
                          f"{scenario.tstop:g} s): that sensor reads once, at t = 0",
                          stacklevel=2)


def checked_options(scenario, options) -> dict:
    """Validate ``[estimators.NAME]`` options by building each estimator from
    ``scenario`` (a :class:`~benchmarks.scenario.Scenario` checking itself)."""
    if not isinstance(options, dict):
        raise InvalidParameterError("estimator_options", options,
                                    "must map estimator names to their settings")
    checked = {}
    for name, settings in options.items():
        cls = estimator_class(name)
        if not isinstance(settings, dict):
            raise InvalidParameterError(f"estimators.{toml_key(name)}", settings,
                                        "must be a section of settings")
        known = cls.option_names()
        for item, value in settings.items():
            if item in cls.owned_fields:
                raise InvalidParameterError(
                    f"estimators.{toml_key(name)}.{item}", plain_value(value),
                    f"is the scenario setting {cls.scenario_defaults[item]}; set that instead")
            if item not in known:
                raise InvalidParameterError(
                    f"estimators.{toml_key(name)}.{item}", plain_value(value),
                    f"is not a setting of {name}; known: {', '.join(known)}")
        checked[name] = dict(settings)
    for name in checked:
        try:
            estimator_class(name).from_scenario(_OptionsView(scenario, checked))
        except InvalidParameterError as err:
            if err.name in checked[name]:
                raise InvalidParameterError(f"estimators.{toml_key(name)}.{err.name}",
                                            err.value, err.rule) from None
            raise
    return checked


class _OptionsView:
    """The scenario as an estimator's ``from_scenario`` sees it, with options
    not yet stored (the scenario is frozen while it validates itself)."""

    def __init__(self, scenario, options: dict):
        self._scenario = scenario
        self.estimator_options = options

    def __getattr__(self, name):
        return getattr(self._scenario, name)
