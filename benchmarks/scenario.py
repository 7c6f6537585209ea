"""Scenarios: every setting of a run, validated where it enters.

:class:`Scenario` holds the workshop's defaults ("Default parameters"), so
``Scenario()`` is the workshop exercise, and the settings that go beyond it:
the gyro's bias model (:mod:`sensors.gyro`), the rotation-noise star tracker
(:mod:`sensors.star_tracker`), and each estimator's own options.

A TOML file may use the workshop's flat keys (the field names), sections, or
both::

    tstop = 3600.0
    dt = 0.1
    initial_state = [1.0, 0.0, 0.0, 0.0]

    [truth]          # inertia_tensor_kg_m2, initial_attitude_quat, initial_rate_radps
    [gyro]           # noise_power, arw_deg_per_rthr or noise_density_deg_per_s_rthz;
                     # bias_random_walk or bias_rw_deg_per_hr_rthr; initial_bias_radps
                     # or initial_bias_deg_per_hr; bias_instability_radps or
                     # bias_instability_deg_per_hr, bias_correlation_time_s;
                     # scale_misalignment; sampling ("sample" or "average")
    [star_tracker]   # model ("workshop" or "rotation"), interval_s, noise_power,
                     # sigma_arcsec, dropout_probability, outages_s, sign, to_body_quat
    [environment]    # epoch, magnetic_field_model ("igrf" or "dipole"),
                     # shadow_model ("conical" or "cylindrical")
    [orbit]          # altitude_km, inclination_deg, raan_deg,
                     # argument_of_latitude_deg, or tle (two lines)
    [site]           # latitude_deg, longitude_deg, altitude_km (a ground IMU)
    [magnetometer]   # interval_s, sigma_nT, bias_nT, soft_iron
    [sun_sensor]     # interval_s, sigma_deg, fov_deg, boresight
    [coarse_sun_sensors]  # interval_s, sigma, normals
    [accelerometer]  # interval_s, sigma_mps2, bias_mps2
    [estimators.mekf]   # any constructor keyword of that estimator
    [estimators."package.module:ClassName"]   # your own estimator's keywords;
                     # its module is imported only with the caller's consent
                     # (``allow_imports``): importing runs its code

Missing keys take the defaults; an unknown key is an error naming its
section. The sections [orbit], [site] and the vector sensors' are off unless
their switching key is given (``altitude_km`` or ``tle``, ``latitude_deg``,
``interval_s``): a section given without it is refused, naming that key,
rather than silently ignored. Then override field by field::

    scenario = Scenario.from_toml("scenarios/default.toml").replace(gyro_noise=1e-4)

Every value is checked on construction; a bad one raises
:class:`~dynamics.validation.InvalidParameterError` (a ``ValueError``) whose
message names the parameter, the value and the rule.
"""
from __future__ import annotations

import dataclasses
import re
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import math

import numpy as np

from dynamics.validation import (
    MISSING,
    InvalidParameterError,
    axis_standard_deviations,
    covariance_matrix,
    finite_number,
    finite_vector,
    inertia_tensor,
    nonzero_quaternion,
    one_of,
    process_exponent,
    standard_deviation,
)
from dynamics.environment import FIELD_MODELS, SHADOW_MODELS, igrf_date
from dynamics.orbit import DEFAULT_EPOCH, TLEOrbit, epoch_datetime, make_orbit, tle_lines
from estimators import ESTIMATORS, resolve_estimator
from sensors.accelerometer import Accelerometer
from sensors.gyro import Gyro
from sensors.magnetometer import Magnetometer
from sensors.star_tracker import NoStarTracker
from sensors.sun_sensor import CUBE_FACES, CoarseSunSensors, FineSunSensor
from sensors.noise import (
    arw_deg_per_rthr_to_rad_per_rts,
    bias_instability_deg_per_hr_to_radps,
    noise_density_deg_per_s_rthz_to_rad_per_rts,
    deg_per_hr_to_radps,
    rrw_deg_per_hr_rthr_to_rad_per_s1p5,
)
from sensors.star_tracker import (
    RotationStarTracker,
    StarTracker,
    on_gyro_grid,
    outage_windows,
    reading_interval,
)

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


def _diag(*values):
    return field(default_factory=lambda: np.diag(values).astype(float))


def _vector(*values):
    return field(default_factory=lambda: np.array(values, dtype=float))


@dataclass(frozen=True, eq=False)
class Scenario:
    """All settings of one run (SI units, radians); the defaults are the workshop's.

    Attributes
    ----------
    tstop : float
        Simulated time, seconds (50).
    dt : float
        Gyro and estimator step, seconds (0.01, i.e. 100 Hz).
    inertia_tensor_kg_m2 : (3, 3) array
        Body inertia, kg m² (diag(1, 2, 3)); 3 numbers mean a diagonal.
    initial_attitude_quat : (4,) array
        True attitude at t = 0, scalar-first ([1, 0, 0, 0]).
    initial_rate_radps : (3,) array
        True body rate at t = 0, rad/s ([0.05, 0.05, 0]).
    gyro_noise : float
        Gyro noise power, rad²/s (1e-5).
    star_tracker_noise : float
        Star tracker noise power per quaternion component (1e-6).
    time_between_measurements : float
        Seconds between star tracker readings, at least dt (0.2); off the
        gyro's grid (not a whole multiple of dt) the readings carry their own
        times and the estimators apply each at its time.
    pc_exponent : float
        EKF process covariance Q = exp(pc_exponent) I₄ (on the workshop's
        sensors -8.7; otherwise derived from the gyro, see
        :meth:`estimators.QuaternionEKF.derived_fields`). None (the default)
        derives it; :attr:`derived_fields` names the fields that were.
    measurement_covariance : (4, 4) array
        EKF measurement covariance R (workshop: I₄; otherwise the star
        tracker's error in quaternion units); a number means that times I₄.
    initial_state : (4,) array
        Initial estimate of every estimator ([1, 0, 0, 0]).
    initial_covariance : float
        EKF P₀ = initial_covariance · I₄ (workshop: 1e-12; otherwise the
        MEKF's default prior of 0.1 rad per axis, (0.1/2)² = 0.0025).
    gyro_bias_random_walk : float
        σ_u, the gyro bias's rate random walk, rad/s^{3/2} (0). ``gyro_noise``
        is σ_v², the square of the angle random walk density.
    gyro_initial_bias_radps : (3,) array
        The gyro's bias at t = 0, rad/s (0).
    gyro_scale_misalignment : (3, 3) array
        Scale factor errors (diagonal) and misalignments (0).
    gyro_sampling : {"sample", "average"}
        A reading is the true rate at the step's start (the workshop's) or
        the average rate over the step, as integrating gyros report
        (:mod:`sensors.gyro`).
    gyro_bias_instability_radps : float
        σ_b of the bias's first-order Gauss–Markov part, rad/s (0: none).
    gyro_bias_correlation_time_s : float
        τ of that part, seconds (3600).
    star_tracker_model : {"workshop", "rotation", "none"}
        Additive quaternion noise of power ``star_tracker_noise`` (the
        workshop's), a small error rotation of ``star_tracker_sigma_arcsec``,
        or no star tracker (vector sensors only).
    star_tracker_sigma_arcsec : (3,) array
        Rotation model: error σ about the sensor x, y (across the boresight)
        and z (roll) axes, arcsec ([6, 6, 40]).
    star_tracker_dropout_probability : float
        Rotation model: chance a scheduled reading is lost (0).
    star_tracker_outages_s : tuple of (start, stop)
        Rotation model: windows without readings, seconds (none).
    star_tracker_sign : {"raw", "canonical"}
        Rotation model: report ``q`` as it comes, or with ``w >= 0`` ("raw").
    star_tracker_to_body_quat : (4,) array
        Rotation model: sensor-to-body rotation ([1, 0, 0, 0]).
    epoch : str or None
        ISO 8601 UTC time of t = 0 (in a file, quoted text or a TOML
        date-time; 1950-2049): the Sun's and the field's epoch. None:
        the element set's epoch with an ``orbit_tle``, else
        :data:`dynamics.orbit.DEFAULT_EPOCH` (the March equinox of 2026).
    magnetic_field_model, shadow_model : str
        "igrf" or "dipole"; "conical" or "cylindrical" (:mod:`dynamics.environment`).
    orbit_altitude_km : float or None
        A circular orbit's altitude (None: no orbit; 100 km to
        :data:`dynamics.orbit.MAX_ALTITUDE_KM`), with
        ``orbit_inclination_deg``, ``orbit_raan_deg`` and
        ``orbit_argument_of_latitude_deg`` at the epoch; or, not both,
        ``orbit_tle``, a two-line element set propagated with SGP4
        (:mod:`dynamics.orbit`), checked over the run when the scenario is.
    site_latitude_deg : float or None
        A ground IMU's geodetic latitude (None: none), with
        ``site_longitude_deg`` and ``site_altitude_km``: the reference frame
        is then east-north-up there (at a pole, the limit along the site's
        meridian, :mod:`dynamics.environment`).
    magnetometer_interval_s, sun_sensor_interval_s, coarse_sun_interval_s,
    accelerometer_interval_s : float or None
        Each vector sensor's interval (a whole multiple of dt; longer than
        ``tstop``, a warning: it reads once, at t = 0), or None for
        no such sensor; their noise and geometry in the fields that follow
        each (:mod:`sensors.magnetometer`, :mod:`sensors.sun_sensor`,
        :mod:`sensors.accelerometer`).
    estimator_options : dict
        ``{estimator name: {keyword: value}}``, from ``[estimators.NAME]``
        sections: each estimator's own settings beyond the scenario's
        (:meth:`estimators.AttitudeEstimator.from_scenario`).
    """

    tstop: float = 50.0
    dt: float = 0.01
    inertia_tensor_kg_m2: np.ndarray = _diag(1.0, 2.0, 3.0)
    initial_attitude_quat: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    initial_rate_radps: np.ndarray = _vector(0.05, 0.05, 0.0)
    gyro_noise: float = 1e-5
    star_tracker_noise: float = 1e-6
    time_between_measurements: float = 0.2
    # The EKF's settings: None derives them (the workshop's values on the
    # workshop's sensors; from the sensors otherwise, see QuaternionEKF).
    pc_exponent: float | None = None
    measurement_covariance: np.ndarray | None = None
    initial_state: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    initial_covariance: float | None = None
    gyro_bias_random_walk: float = 0.0
    gyro_initial_bias_radps: np.ndarray = _vector(0.0, 0.0, 0.0)
    gyro_scale_misalignment: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    gyro_sampling: str = "sample"
    gyro_bias_instability_radps: float = 0.0
    gyro_bias_correlation_time_s: float = 3600.0
    star_tracker_model: str = "workshop"
    star_tracker_sigma_arcsec: np.ndarray = _vector(6.0, 6.0, 40.0)
    star_tracker_dropout_probability: float = 0.0
    star_tracker_outages_s: tuple = ()
    star_tracker_sign: str = "raw"
    star_tracker_to_body_quat: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    epoch: str | None = None
    magnetic_field_model: str = "igrf"
    shadow_model: str = "conical"
    orbit_altitude_km: float | None = None
    orbit_inclination_deg: float = 97.4
    orbit_raan_deg: float = 0.0
    orbit_argument_of_latitude_deg: float = 0.0
    orbit_tle: tuple = ()
    site_latitude_deg: float | None = None
    site_longitude_deg: float = 0.0
    site_altitude_km: float = 0.0
    magnetometer_interval_s: float | None = None
    magnetometer_sigma_nT: float = 100.0
    magnetometer_bias_nT: np.ndarray = _vector(0.0, 0.0, 0.0)
    magnetometer_soft_iron: np.ndarray = _diag(1.0, 1.0, 1.0)
    sun_sensor_interval_s: float | None = None
    sun_sensor_sigma_deg: float = 0.1
    sun_sensor_fov_deg: float = 70.0
    sun_sensor_boresight: np.ndarray = _vector(0.0, 0.0, 1.0)
    coarse_sun_interval_s: float | None = None
    coarse_sun_sigma: float = 0.01
    coarse_sun_normals: np.ndarray = field(default_factory=lambda: np.array(CUBE_FACES))
    accelerometer_interval_s: float | None = None
    accelerometer_sigma_mps2: float = 0.01
    accelerometer_bias_mps2: np.ndarray = _vector(0.0, 0.0, 0.0)
    estimator_options: dict = field(default_factory=dict)

    def __post_init__(self):
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        set_("dt", finite_number("dt", self.dt, strictly_positive=True))
        set_("tstop", finite_number("tstop", self.tstop, strictly_positive=True))
        if self.tstop < self.dt:
            raise InvalidParameterError("tstop", self.tstop, f"must be >= dt = {self.dt:g}")
        if self.tstop / self.dt >= MAX_STEPS:
            steps = self.tstop / self.dt
            raise InvalidParameterError(
                "tstop", self.tstop, (f"makes {steps:,.0f}" if steps < 1e15 else
                                      f"makes {steps:.3g}") + f" steps of dt = {self.dt:g}; at "
                f"most {MAX_STEPS:,} steps (tstop = {MAX_STEPS * self.dt:,.0f} s)")
        set_("inertia_tensor_kg_m2", inertia_tensor("inertia_tensor_kg_m2",
                                                    self.inertia_tensor_kg_m2))
        set_("initial_attitude_quat", nonzero_quaternion("initial_attitude_quat",
                                                         self.initial_attitude_quat))
        set_("initial_rate_radps", finite_vector("initial_rate_radps", self.initial_rate_radps, 3))
        if np.abs(self.initial_rate_radps).max() > MAX_RATE_RADPS:
            raise InvalidParameterError("initial_rate_radps", self.initial_rate_radps,
                                        f"each component must be within ±{MAX_RATE_RADPS:g} rad/s "
                                        "(a spacecraft, not a centrifuge)")
        set_("gyro_noise", finite_number("gyro_noise", self.gyro_noise, minimum=0.0))
        if self.gyro_noise / self.dt > MAX_GYRO_NOISE_RADPS ** 2:
            raise InvalidParameterError(
                "gyro_noise", self.gyro_noise, f"makes the reading noise √(p/dt) = "
                f"{math.sqrt(self.gyro_noise / self.dt):.3g} rad/s per sample; at most "
                f"{MAX_GYRO_NOISE_RADPS:g} rad/s (gyro_noise <= "
                f"{MAX_GYRO_NOISE_RADPS ** 2 * self.dt:g} with dt = {self.dt:g})")
        set_("star_tracker_noise", finite_number("star_tracker_noise", self.star_tracker_noise,
                                                 minimum=0.0))
        if self.star_tracker_noise / self.dt > MAX_STAR_NOISE ** 2:
            raise InvalidParameterError(
                "star_tracker_noise", self.star_tracker_noise, f"makes the reading noise "
                f"√(p/dt) = {math.sqrt(self.star_tracker_noise / self.dt):.3g} per quaternion "
                f"component; at most {MAX_STAR_NOISE:g}, beyond which a reading is noise alone "
                f"(star_tracker_noise <= {MAX_STAR_NOISE ** 2 * self.dt:g} with dt = "
                f"{self.dt:g})")
        set_("time_between_measurements", reading_interval(self.time_between_measurements,
                                                           self.dt))
        set_("initial_state", nonzero_quaternion("initial_state", self.initial_state))
        one_of("star_tracker_model", self.star_tracker_model, STAR_TRACKER_MODELS)
        set_("star_tracker_outages_s", outage_windows("star_tracker_outages_s",
                                                      self.star_tracker_outages_s))
        self._check_standard_deviations()
        # The sensor classes validate (and normalise) their own settings.
        gyro, star_tracker = self.build_gyro(), self.build_star_tracker()
        set_("gyro_bias_random_walk", gyro.bias_random_walk)
        set_("gyro_initial_bias_radps", gyro.initial_bias_radps)
        set_("gyro_scale_misalignment", np.zeros((3, 3)) if gyro.scale_misalignment is None
             else gyro.scale_misalignment)
        # The rotation tracker's settings are checked whichever model is chosen:
        # a file that switches models later should not hide a bad value.
        rotation = star_tracker if star_tracker.model == "rotation" else \
            self._rotation_star_tracker()
        set_("star_tracker_sigma_arcsec", rotation.sigma_arcsec)
        set_("star_tracker_dropout_probability", rotation.dropout_probability)
        set_("star_tracker_to_body_quat", rotation.sensor_to_body_quat)
        self._check_environment()
        self._warn_of_idle_sensors()
        self._derive_estimator_fields()
        set_("pc_exponent", process_exponent("pc_exponent", self.pc_exponent))
        set_("measurement_covariance", covariance_matrix("measurement_covariance",
                                                         self.measurement_covariance))
        set_("initial_covariance", finite_number("initial_covariance", self.initial_covariance,
                                                 strictly_positive=True))
        set_("estimator_options", _checked_options(self, self.estimator_options))

    def _derive_estimator_fields(self) -> None:
        """Fill the estimators' own fields left None with what each estimator
        derives from this scenario's sensors (``derived_fields``), and note
        which they were (:attr:`derived_fields`, kept by :meth:`replace` so a
        changed sensor derives them anew)."""
        derived = set()
        for cls in dict.fromkeys(ESTIMATORS.values()):
            missing = [cls.scenario_defaults[keyword] for keyword in cls.owned_fields
                       if getattr(self, cls.scenario_defaults[keyword]) is None]
            if not missing:
                continue
            values = cls.derived_fields(self)
            for name in missing:
                object.__setattr__(self, name, values[name])
                derived.add(name)
        object.__setattr__(self, "derived_fields", frozenset(derived))

    def _check_standard_deviations(self) -> None:
        """The σ the sensors square into variances: refused here while the
        square would overflow (the sensors check the rest)."""
        standard_deviation("gyro_bias_random_walk", self.gyro_bias_random_walk)
        standard_deviation("gyro_bias_instability_radps", self.gyro_bias_instability_radps)
        if np.ndim(self.star_tracker_sigma_arcsec) == 1:     # one σ per sensor axis
            axis_standard_deviations("star_tracker_sigma_arcsec", self.star_tracker_sigma_arcsec)

    def build_gyro(self) -> Gyro:
        """The gyro this scenario describes."""
        return Gyro(self.gyro_noise, self.dt, bias_random_walk=self.gyro_bias_random_walk,
                    initial_bias_radps=self.gyro_initial_bias_radps,
                    scale_misalignment=self.gyro_scale_misalignment,
                    sampling=self.gyro_sampling,
                    bias_instability_radps=self.gyro_bias_instability_radps,
                    bias_correlation_time_s=self.gyro_bias_correlation_time_s)

    def build_star_tracker(self) -> StarTracker | RotationStarTracker | NoStarTracker:
        """The star tracker this scenario describes."""
        if self.star_tracker_model == "workshop":
            return StarTracker(self.star_tracker_noise, self.time_between_measurements, self.dt)
        if self.star_tracker_model == "none":
            return NoStarTracker(self.time_between_measurements, self.dt)
        return self._rotation_star_tracker()

    def _check_environment(self) -> None:
        """The orbit, the site and the vector sensors: each built once (its
        class checks its settings), and each sensor where it can read."""
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        if self.epoch is not None:
            set_("epoch", epoch_datetime("environment.epoch", self.epoch).isoformat())
        one_of("environment.magnetic_field_model", self.magnetic_field_model, FIELD_MODELS)
        one_of("environment.shadow_model", self.shadow_model, SHADOW_MODELS)
        set_("orbit_tle", tle_lines("orbit.tle", self.orbit_tle))
        if self.orbit_tle and self.orbit_altitude_km is not None:
            raise InvalidParameterError("orbit.altitude_km", self.orbit_altitude_km,
                                        "cannot be given with orbit.tle: the orbit is a circular "
                                        "one (altitude_km) or an element set's (tle), not both")
        orbit, site = self.build_orbit(), self.site
        if orbit is not None and site is not None:
            raise InvalidParameterError("site.latitude_deg", self.site_latitude_deg,
                                        "cannot be set with an [orbit]: a scenario is in orbit "
                                        "or on the ground")
        if site is not None and self.magnetic_field_model == "dipole":
            raise InvalidParameterError("environment.magnetic_field_model", "dipole",
                                        "is for orbits; a [site] on the ground takes IGRF")
        if isinstance(orbit, TLEOrbit):
            # Here, not steps into a run: show-config must refuse a decay too.
            steps = np.arange(self.n_steps) if self.n_steps <= ORBIT_CHECK_STEPS else \
                np.unique(np.linspace(0, self.n_steps - 1, ORBIT_CHECK_STEPS).round())
            orbit.check_propagation(steps * self.dt)
        self._check_sensor_places(orbit, site)
        if self.has_vector_sensors and (orbit is not None or site is not None):
            igrf_date(self.epoch_moment)        # warns if the field is held at IGRF's end

    def _check_sensor_places(self, orbit, site) -> None:
        """Each vector sensor where it can read; and some attitude sensor."""
        sensors = self.build_vector_sensors()
        for sensor in sensors:
            where = {"accelerometer": site, "sun_sensor": orbit,
                     "coarse_sun_sensors": orbit}.get(sensor.name, orbit or site)
            if where is None:
                needs = ("a [site] (on the ground; in orbit it reads no gravity)"
                         if sensor.name == "accelerometer" else "an [orbit] (for the Sun)"
                         if sensor.name != "magnetometer" else "an [orbit] or a [site]")
                raise InvalidParameterError(f"{sensor.name}.interval_s", sensor.interval_s,
                                            f"needs {needs}")
        if self.star_tracker_model == "none" and not sensors:
            raise InvalidParameterError("star_tracker.model", "none", "leaves no attitude "
                                        "sensor: add a vector sensor ([magnetometer], "
                                        "[sun_sensor], …) or choose a star tracker model")

    def _warn_of_idle_sensors(self) -> None:
        """A sensor whose interval is longer than the run reads once, at t = 0.
        Said, not refused: shortening a run (``--tstop``) for a quick look
        is ordinary, and the run is well defined; but it is rarely meant."""
        intervals = [(f"{sensor.name}.interval_s", sensor.interval_s)
                     for sensor in self.build_vector_sensors()]
        if self.star_tracker_model != "none":
            intervals.insert(0, ("star_tracker.interval_s", self.time_between_measurements))
        for name, interval in intervals:
            if interval > self.tstop:
                warnings.warn(f"{name} = {interval:g} s is longer than the run (tstop = "
                              f"{self.tstop:g} s): that sensor reads once, at t = 0",
                              stacklevel=2)

    def build_orbit(self):
        """The :class:`~dynamics.orbit.CircularOrbit` or
        :class:`~dynamics.orbit.TLEOrbit` this scenario describes, or None."""
        return make_orbit(**self.orbit_settings)

    @property
    def orbit_settings(self) -> dict:
        """The keywords of :func:`dynamics.orbit.make_orbit` (hashable values)."""
        return {"epoch": self.epoch_moment,
                "tle": tuple(self.orbit_tle), "altitude_km": self.orbit_altitude_km,
                "inclination_deg": self.orbit_inclination_deg, "raan_deg": self.orbit_raan_deg,
                "argument_of_latitude_deg": self.orbit_argument_of_latitude_deg}

    @property
    def epoch_moment(self):
        """Time zero as a UTC datetime: the given epoch, or the element set's,
        or :data:`dynamics.orbit.DEFAULT_EPOCH`."""
        if self.epoch is not None:
            return epoch_datetime("environment.epoch", self.epoch)
        if self.orbit_tle:
            return TLEOrbit(self.orbit_tle).element_epoch
        return epoch_datetime("environment.epoch", DEFAULT_EPOCH)

    @property
    def site(self) -> tuple | None:
        """``(latitude_deg, longitude_deg, altitude_km)`` of a ground IMU, or None."""
        if self.site_latitude_deg is None:
            return None
        values = []
        for name, value, low, high in (("latitude_deg", self.site_latitude_deg, -90.0, 90.0),
                                       ("longitude_deg", self.site_longitude_deg, -360.0, 360.0),
                                       ("altitude_km", self.site_altitude_km, -1.0, 100.0)):
            number = finite_number(f"site.{name}", value)
            if not low <= number <= high:
                raise InvalidParameterError(f"site.{name}", value,
                                            f"must be within {low:g} and {high:g}")
            values.append(number)
        return tuple(values)

    def build_vector_sensors(self) -> list:
        """The vector sensors this scenario has, in a fixed order
        (magnetometer, fine sun sensor, coarse sun sensors, accelerometer)."""
        sensors = []
        if self.magnetometer_interval_s is not None:
            sensors.append(Magnetometer(self.magnetometer_sigma_nT,
                                        self._interval("magnetometer"), self.dt,
                                        bias_nT=self.magnetometer_bias_nT,
                                        soft_iron=self.magnetometer_soft_iron))
        if self.sun_sensor_interval_s is not None:
            sensors.append(FineSunSensor(self.sun_sensor_sigma_deg, self._interval("sun_sensor"),
                                         self.dt, fov_deg=self.sun_sensor_fov_deg,
                                         boresight=self.sun_sensor_boresight))
        if self.coarse_sun_interval_s is not None:
            sensors.append(CoarseSunSensors(self.coarse_sun_sigma,
                                            self._interval("coarse_sun"), self.dt,
                                            normals=self.coarse_sun_normals))
        if self.accelerometer_interval_s is not None:
            sensors.append(Accelerometer(self.accelerometer_sigma_mps2,
                                         self._interval("accelerometer"), self.dt,
                                         bias_mps2=self.accelerometer_bias_mps2))
        return sensors

    def _interval(self, prefix: str) -> float:
        """A vector sensor's interval: a whole multiple of ``dt`` (its section named)."""
        from sensors.star_tracker import steps_between_readings
        section = {"coarse_sun": "coarse_sun_sensors"}.get(prefix, prefix)
        name = f"{section}.interval_s"
        value = finite_number(name, getattr(self, f"{prefix}_interval_s"), strictly_positive=True)
        try:
            steps_between_readings(value, self.dt)
        except InvalidParameterError as err:
            raise InvalidParameterError(name, value, err.rule) from None
        return value

    @property
    def has_vector_sensors(self) -> bool:
        return any(getattr(self, name) is not None for name in (
            "magnetometer_interval_s", "sun_sensor_interval_s", "coarse_sun_interval_s",
            "accelerometer_interval_s"))

    def _rotation_star_tracker(self) -> RotationStarTracker:
        return RotationStarTracker(
            self.star_tracker_sigma_arcsec, self.time_between_measurements, self.dt,
            dropout_probability=self.star_tracker_dropout_probability,
            outages_s=self.star_tracker_outages_s, sign=self.star_tracker_sign,
            sensor_to_body_quat=self.star_tracker_to_body_quat)

    @property
    def gyro_filter_bias_random_walk(self) -> float:
        """σ_u (rad/s^{3/2}) a filter with a random-walk bias takes for this
        gyro: its random walk, and its Gauss–Markov part as the equivalent
        driving noise (:func:`sensors.gyro.equivalent_bias_random_walk`)."""
        return self.build_gyro().filter_bias_random_walk

    @property
    def star_tracker_attitude_covariance_rad2(self) -> np.ndarray:
        """Covariance (rad²) of a star tracker reading's body-frame error: what
        a filter matched to this scenario takes as its ``R``."""
        return self.build_star_tracker().attitude_covariance_rad2

    @property
    def is_workshop_sensors(self) -> bool:
        """True when the sensors are the workshop's: its star tracker model, and
        a gyro that samples the rate and has no bias model. Estimators then
        take the exercise's settings; on any other scenario they derive
        theirs from the sensors (each estimator's ``settings_from_scenario``)."""
        return (self.star_tracker_model == "workshop" and self.gyro_sampling == "sample"
                and not self.build_gyro().has_bias_model and not self.has_vector_sensors)

    @property
    def readings_on_gyro_grid(self) -> bool:
        """Whether the tracker's interval is a whole multiple of ``dt`` (its
        readings fall on gyro steps); otherwise they carry their own times."""
        return on_gyro_grid(self.time_between_measurements, self.dt)

    @property
    def n_steps(self) -> int:
        """``N = round(tstop / dt) + 1`` samples, ``t_k = k dt``."""
        return round(self.tstop / self.dt) + 1

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.n_steps) * self.dt

    def replace(self, **changes) -> "Scenario":
        """A copy with some fields changed (validated like the original)."""
        unknown = set(changes) - set(field_names())
        if unknown:
            name = sorted(unknown)[0]
            raise InvalidParameterError(name, changes[name], "is not a scenario setting; "
                                        f"known: {', '.join(field_names())}")
        for name in self.derived_fields:
            changes.setdefault(name, None)       # derived again from the new sensors
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """Plain-Python values (lists for arrays and tuples), e.g. for JSON or TOML."""
        return {name: _plain(getattr(self, name)) for name in field_names()}

    @classmethod
    def from_toml(cls, path, *, allow_imports=()) -> "Scenario":
        """Load a scenario file: flat field names and/or sections (see the
        module docstring); missing keys take the defaults.

        ``path`` may be a list of files, laid over each other in order: a
        later file's setting overrides an earlier one's key by key (in any of
        its units), and its ``[estimators.NAME]`` keys override those of the
        same section. So a change to try is a small file over the full one.

        A section ``[estimators."package.module:ClassName"]`` imports that
        module, which runs its code: it is refused, before anything is
        imported, unless ``allow_imports`` (module names, or
        ``package.module:ClassName`` specs, which allow their module) names
        the module. Registry names (``[estimators.mekf]``) need no consent.
        """
        paths = [path] if isinstance(path, (str, Path)) else list(path)
        if not paths:
            raise InvalidParameterError("scenario", paths, "must name at least one file")
        flat, options, present = {}, {}, {}
        for each in paths:
            data = read_toml(each)
            check_import_consent(data, allow_imports)
            layer = flatten_sections(data)
            for name, settings in layer.pop("estimator_options", {}).items():
                options.setdefault(name, {}).update(settings)
            for section in SWITCHES:
                given = _section_keys(data, section)
                if given is not None:
                    present.setdefault(section, []).extend(given)
            # A later file's orbit replaces an earlier's, circular or element set.
            if "orbit_tle" in layer:
                for name in CIRCULAR_ORBIT_FIELDS:
                    flat.pop(name, None)
            if "orbit_altitude_km" in layer:
                flat.pop("orbit_tle", None)
            flat.update(layer)
        _check_switches(present, flat)
        return cls().replace(**flat, **({"estimator_options": options} if options else {}))

    def with_estimator_settings(self, path, *, allow_imports=()) -> "Scenario":
        """This scenario with the ``[estimators.NAME]`` sections of the file
        ``path`` laid over it (for scenarios made otherwise, e.g. from a
        recording); any other key in the file is refused. ``allow_imports``
        as for :meth:`from_toml`."""
        data = read_toml(path)
        check_import_consent(data, allow_imports)
        for key, value in data.items():
            if key != "estimators":
                raise InvalidParameterError(key, _plain(value), "only [estimators.NAME] "
                                            "sections may be given here; the rest is set "
                                            "for you")
        flat = flatten_sections(data)
        options = {name: dict(settings) for name, settings in self.estimator_options.items()}
        for name, settings in flat.pop("estimator_options", {}).items():
            options.setdefault(name, {}).update(settings)
        return self.replace(**flat, estimator_options=options)


def read_toml(path) -> dict:
    """A TOML file's document; a missing, unreadable or malformed file is one
    clear error naming it."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise InvalidParameterError("scenario", str(path), "file does not exist") from None
    except OSError as err:
        raise InvalidParameterError("scenario", str(path),
                                    f"cannot be read ({err.strerror})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise InvalidParameterError("scenario", str(path),
                                    f"must be valid TOML ({err})") from None


def allowed_modules(allow_imports) -> frozenset[str]:
    """The modules ``allow_imports`` consents to import: module names, or
    ``package.module:ClassName`` specs (which allow their module); one string
    is one name."""
    rule = "must be module names or package.module:ClassName specs"
    items = [allow_imports] if isinstance(allow_imports, str) else allow_imports
    try:
        items = list(items)
    except TypeError:
        raise InvalidParameterError("allow_imports", allow_imports, rule) from None
    for item in items:
        if not isinstance(item, str) or not item.partition(":")[0]:
            raise InvalidParameterError("allow_imports", item, rule)
    return frozenset(item.partition(":")[0] for item in items)


def check_import_consent(data: dict, allow_imports) -> None:
    """Refuse a TOML document's ``[estimators."package.module:ClassName"]``
    section whose module ``allow_imports`` does not allow, importing nothing:
    reading a data file must not run code the user did not agree to."""
    sections = data.get("estimators")
    if not isinstance(sections, dict):
        return                   # flatten_sections names what is wrong with it
    allowed = allowed_modules(allow_imports)
    for name, settings in sections.items():
        module, colon, _ = name.partition(":")
        if name in ESTIMATORS or not colon or module in allowed:
            continue
        raise InvalidParameterError(
            f"estimators.{_key(name)}", _plain(settings),
            f"reading the file would import {module} and run its code; allow it with "
            f"--allow-import {module} or by naming {name} in --estimators (from Python: "
            f"allow_imports=[{module!r}])")


def field_names() -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(Scenario))


#: The workshop's own settings: the keys of ``scenarios/default.toml``.
WORKSHOP_FIELDS = ("tstop", "dt", "inertia_tensor_kg_m2", "initial_attitude_quat",
                   "initial_rate_radps", "gyro_noise", "star_tracker_noise",
                   "time_between_measurements", "pc_exponent", "measurement_covariance",
                   "initial_state", "initial_covariance")


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain(item) for item in value]
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    return value


@dataclass(frozen=True)
class SectionKey:
    """A key of a TOML section: the field it sets, for datasheet units the
    conversion to the field's SI unit, and whether ``sweep`` can vary it
    (``--param SECTION.KEY``, one number per run; for a per-axis σ, a
    number is the same σ on every axis)."""

    field: str
    convert: object = None
    sweepable: bool = False


@dataclass(frozen=True)
class Setting:
    """One scenario setting, declared once: its :class:`Scenario` field, where
    a TOML file sets it (``section``, ``key``; the flat field name always
    works too), its unit and meaning, its command-line flag, whether a run of
    a batch may vary it (a :class:`~benchmarks.engine.RunTable` column) and
    whether ``sweep`` can vary it (under ``sweep`` with ``legend``, and as
    ``SECTION.KEY``), and which star tracker ``model`` alone reads it (None:
    every one). The TOML sections (:data:`SECTIONS`), the flags, the per-run
    columns, the sweepable parameters and the refusal of a setting the
    chosen model ignores are made from these."""

    field: str
    section: str | None            # None: a top-level key only
    key: str
    unit: str
    doc: str
    flag: str | None = None
    per_run: bool = False
    sweep: str | None = None
    legend: str = ""
    sweepable: bool = False
    model: str | None = None


#: Every setting of a scenario but the estimators' own options, in TOML order.
#: The EKF's settings live in ``[estimators.ekf]`` (its ``owned_fields``);
#: the workshop's flat keys keep working.
SETTINGS = (
    Setting("tstop", None, "tstop", "s", "simulated time", flag="--tstop"),
    Setting("dt", None, "dt", "s", "gyro and estimator step", flag="--dt"),
    Setting("initial_state", None, "initial_state", "", "initial estimate of every estimator"),
    Setting("inertia_tensor_kg_m2", "truth", "inertia_tensor_kg_m2", "kg m^2", "body inertia"),
    Setting("initial_attitude_quat", "truth", "initial_attitude_quat", "",
            "true attitude at t = 0, scalar-first"),
    Setting("initial_rate_radps", "truth", "initial_rate_radps", "rad/s",
            "true body rate at t = 0"),
    Setting("gyro_noise", "gyro", "noise_power", "rad^2/s", "gyro noise power",
            flag="--gyro-noise", per_run=True, sweep="gyro-noise", legend="Noise = {value:g}",
            sweepable=True),
    Setting("gyro_bias_random_walk", "gyro", "bias_random_walk", "rad/s^1.5",
            "gyro bias rate random walk", sweepable=True),
    Setting("gyro_initial_bias_radps", "gyro", "initial_bias_radps", "rad/s",
            "gyro bias at t = 0"),
    Setting("gyro_scale_misalignment", "gyro", "scale_misalignment", "",
            "scale factor errors and misalignments"),
    Setting("gyro_sampling", "gyro", "sampling", "",
            "sample (the rate at the step's start) or average (over the step)"),
    Setting("gyro_bias_instability_radps", "gyro", "bias_instability_radps", "rad/s",
            "sigma of the bias's Gauss-Markov part", sweepable=True),
    Setting("gyro_bias_correlation_time_s", "gyro", "bias_correlation_time_s", "s",
            "correlation time of the bias's Gauss-Markov part", sweepable=True),
    Setting("star_tracker_model", "star_tracker", "model", "", "workshop or rotation"),
    Setting("star_tracker_noise", "star_tracker", "noise_power", "",
            "star tracker noise power (workshop model)", flag="--star-tracker-noise",
            per_run=True, sweep="star-tracker-noise", legend="ST noise = {value:g}",
            sweepable=True, model="workshop"),
    Setting("time_between_measurements", "star_tracker", "interval_s", "s",
            "star tracker interval (>= dt; its own clock)", flag="--time-between-measurements",
            per_run=True, sweep="time-between-measurements", legend="ST every {value:g} s",
            sweepable=True),
    Setting("star_tracker_sigma_arcsec", "star_tracker", "sigma_arcsec", "arcsec",
            "rotation model: error sigma about sensor x, y, z", sweepable=True,
            model="rotation"),
    Setting("star_tracker_dropout_probability", "star_tracker", "dropout_probability", "",
            "rotation model: chance a reading is lost", sweepable=True, model="rotation"),
    Setting("star_tracker_outages_s", "star_tracker", "outages_s", "s",
            "rotation model: windows without readings", model="rotation"),
    Setting("star_tracker_sign", "star_tracker", "sign", "", "rotation model: raw or canonical",
            model="rotation"),
    Setting("star_tracker_to_body_quat", "star_tracker", "to_body_quat", "",
            "rotation model: sensor-to-body rotation", model="rotation"),
    Setting("epoch", "environment", "epoch", "", "UTC date and time of t = 0 (ISO 8601)"),
    Setting("magnetic_field_model", "environment", "magnetic_field_model", "",
            "igrf or dipole"),
    Setting("shadow_model", "environment", "shadow_model", "", "conical or cylindrical"),
    Setting("orbit_altitude_km", "orbit", "altitude_km", "km", "circular orbit's altitude"),
    Setting("orbit_inclination_deg", "orbit", "inclination_deg", "deg", "inclination"),
    Setting("orbit_raan_deg", "orbit", "raan_deg", "deg", "right ascension of the node"),
    Setting("orbit_argument_of_latitude_deg", "orbit", "argument_of_latitude_deg", "deg",
            "argument of latitude at the epoch"),
    Setting("orbit_tle", "orbit", "tle", "", "two-line element set (SGP4)"),
    Setting("site_latitude_deg", "site", "latitude_deg", "deg", "ground site's latitude"),
    Setting("site_longitude_deg", "site", "longitude_deg", "deg", "ground site's longitude"),
    Setting("site_altitude_km", "site", "altitude_km", "km", "ground site's altitude"),
    Setting("magnetometer_interval_s", "magnetometer", "interval_s", "s",
            "magnetometer interval (a multiple of dt)"),
    Setting("magnetometer_sigma_nT", "magnetometer", "sigma_nT", "nT",
            "magnetometer noise sigma per axis", sweepable=True),
    Setting("magnetometer_bias_nT", "magnetometer", "bias_nT", "nT", "hard-iron bias"),
    Setting("magnetometer_soft_iron", "magnetometer", "soft_iron", "", "soft-iron matrix"),
    Setting("sun_sensor_interval_s", "sun_sensor", "interval_s", "s",
            "fine sun sensor interval (a multiple of dt)"),
    Setting("sun_sensor_sigma_deg", "sun_sensor", "sigma_deg", "deg",
            "fine sun sensor noise sigma per axis", sweepable=True),
    Setting("sun_sensor_fov_deg", "sun_sensor", "fov_deg", "deg", "field of view half-angle"),
    Setting("sun_sensor_boresight", "sun_sensor", "boresight", "", "boresight, body frame"),
    Setting("coarse_sun_interval_s", "coarse_sun_sensors", "interval_s", "s",
            "coarse sun sensors' interval (a multiple of dt)"),
    Setting("coarse_sun_sigma", "coarse_sun_sensors", "sigma", "",
            "current noise sigma, fraction of full sun", sweepable=True),
    Setting("coarse_sun_normals", "coarse_sun_sensors", "normals", "",
            "faces' outward normals, body frame"),
    Setting("accelerometer_interval_s", "accelerometer", "interval_s", "s",
            "accelerometer interval (a multiple of dt)"),
    Setting("accelerometer_sigma_mps2", "accelerometer", "sigma_mps2", "m/s^2",
            "accelerometer noise sigma per axis", sweepable=True),
    Setting("accelerometer_bias_mps2", "accelerometer", "bias_mps2", "m/s^2",
            "accelerometer bias"),
    Setting("pc_exponent", "estimators.ekf", "pc_exponent", "",
            "EKF process covariance Q = exp(X) I4", flag="--pc-exponent", per_run=True,
            sweep="pc-exponent", legend="{label}, pc exponent = {value:g}"),
    Setting("measurement_covariance", "estimators.ekf", "measurement_covariance", "",
            "EKF measurement covariance R"),
    Setting("initial_covariance", "estimators.ekf", "initial_covariance", "",
            "EKF P0 = initial_covariance I4"),
)

#: Keys in datasheet units: section → key → the setting's field and the conversion.
DATASHEET_KEYS = {
    "gyro": {
        "arw_deg_per_rthr": SectionKey(
            "gyro_noise", lambda v: arw_deg_per_rthr_to_rad_per_rts(
                standard_deviation("gyro.arw_deg_per_rthr", v)) ** 2, sweepable=True),
        "bias_rw_deg_per_hr_rthr": SectionKey(
            "gyro_bias_random_walk", lambda v: rrw_deg_per_hr_rthr_to_rad_per_s1p5(
                standard_deviation("gyro.bias_rw_deg_per_hr_rthr", v)), sweepable=True),
        "noise_density_deg_per_s_rthz": SectionKey(
            "gyro_noise", lambda v: noise_density_deg_per_s_rthz_to_rad_per_rts(
                standard_deviation("gyro.noise_density_deg_per_s_rthz", v)) ** 2,
            sweepable=True),
        "bias_instability_deg_per_hr": SectionKey(
            "gyro_bias_instability_radps", lambda v: bias_instability_deg_per_hr_to_radps(
                standard_deviation("gyro.bias_instability_deg_per_hr", v)), sweepable=True),
        "initial_bias_deg_per_hr": SectionKey(
            "gyro_initial_bias_radps", lambda v: deg_per_hr_to_radps(
                finite_vector("gyro.initial_bias_deg_per_hr", v, 3))),
    },
}
#: How a key converts its value, where a number stands for more.
_CONVERSIONS = {
    # A number is the same σ on every sensor axis.
    "star_tracker_sigma_arcsec": lambda v: [v] * 3 if np.ndim(v) == 0 else v,
}


def _sections() -> dict:
    """section → key → what it sets: the declared settings, then the datasheet keys."""
    sections = {}
    for setting in SETTINGS:
        if setting.section is not None and not setting.section.startswith("estimators."):
            sections.setdefault(setting.section, {})[setting.key] = SectionKey(
                setting.field, _CONVERSIONS.get(setting.field), setting.sweepable)
    for section, keys in DATASHEET_KEYS.items():
        sections[section].update(keys)
    return sections


#: section → key → what it sets.
SECTIONS = _sections()


def flatten_sections(data: dict) -> dict:
    """Turn a TOML document's sections into field values (flat keys pass through).

    ``[estimators.NAME]`` keys that an estimator owns as a scenario field
    (the EKF's ``pc_exponent``, …) set that field; the others become
    ``estimator_options[NAME]``. A key set twice (flat and in a section, or
    in two units) is an error.
    """
    flat, options = {}, {}

    def put(field_name, value, where):
        if field_name in flat:
            raise InvalidParameterError(where, _plain(value), f"sets {field_name}, which "
                                        "is already set elsewhere in the file")
        flat[field_name] = value

    for key, value in data.items():
        if key in SECTIONS:
            if not isinstance(value, dict):
                raise InvalidParameterError(key, value, "must be a [section] of keys")
            for item, item_value in value.items():
                spec = SECTIONS[key].get(item)
                if spec is None:
                    raise InvalidParameterError(f"{key}.{item}", item_value,
                                                f"is not a setting of [{key}]; known: "
                                                f"{', '.join(SECTIONS[key])}")
                converted = spec.convert(item_value) if spec.convert else item_value
                put(spec.field, converted, f"{key}.{item}")
        elif key == "estimators":
            if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
                raise InvalidParameterError(key, value, "must hold [estimators.NAME] sections")
            for name, settings in value.items():
                cls = _estimator_class(name)
                for item, item_value in settings.items():
                    if item in cls.owned_fields:
                        put(cls.scenario_defaults[item], item_value, f"estimators.{_key(name)}.{item}")
                    else:
                        options.setdefault(name, {})[item] = item_value
        else:
            put(key, value, key)
    if options:
        put("estimator_options", options, "estimators")
    return flat


#: The sections that are off unless a key switches them on: that key (for
#: [orbit], either of two). A section given without it is refused.
SWITCHES = {"orbit": ("altitude_km", "tle"), "site": ("latitude_deg",),
            "magnetometer": ("interval_s",), "sun_sensor": ("interval_s",),
            "coarse_sun_sensors": ("interval_s",), "accelerometer": ("interval_s",)}
#: A circular orbit's settings: none of them may stand beside an element set.
CIRCULAR_ORBIT_FIELDS = ("orbit_altitude_km", "orbit_inclination_deg", "orbit_raan_deg",
                         "orbit_argument_of_latitude_deg")


def _section_keys(data: dict, section: str) -> list[str] | None:
    """The keys a TOML document gives ``section``, in the section or as flat
    field names (``magnetometer_sigma_nT``); None if it gives it nothing and
    has no such section."""
    keys = list(data[section]) if isinstance(data.get(section), dict) else None
    for setting in SETTINGS:
        if setting.section == section and setting.field in data:
            keys = (keys or []) + [setting.key]
    return keys


def _check_switches(present: dict, flat: dict) -> None:
    """Refuse a section that is given but off (its switching key missing:
    its other keys would be silently ignored), and a circular orbit's
    setting beside an element set."""
    fields = {(setting.section, setting.key): setting.field for setting in SETTINGS}
    for section, given in present.items():
        switches = SWITCHES[section]
        if any(fields[section, key] in flat for key in switches):
            continue
        what = ", ".join(dict.fromkeys(given)) or "no keys"
        needed = " or ".join(switches)
        raise InvalidParameterError(
            f"{section}.{switches[0]}", MISSING,
            f"must be given: [{section}] is in the file ({what}) but without {needed} it is off "
            f"and its settings would be ignored; give {needed}, or leave the section out")
    if "orbit_tle" in flat:
        for name in CIRCULAR_ORBIT_FIELDS:
            if name in flat:
                key = name.removeprefix("orbit_")
                raise InvalidParameterError(
                    f"orbit.{key}", _plain(flat[name]), "is a circular orbit's setting, and "
                    "orbit.tle is given: an element set carries its own orbit; give one or the "
                    "other")


def _key(name: str) -> str:
    """``name`` as a TOML key: bare if it can be, quoted otherwise."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else f'"{name}"'


def _estimator_class(name: str):
    """The class of an ``[estimators.NAME]`` section: a registry name, or a
    user's own as ``[estimators."package.module:ClassName"]``."""
    if name in ESTIMATORS:
        return ESTIMATORS[name]
    if ":" not in name:
        raise InvalidParameterError(f"estimators.{_key(name)}", name,
                                    f"is not an estimator; known: {', '.join(ESTIMATORS)}, "
                                    "or \"package.module:ClassName\" for your own")
    try:
        return resolve_estimator(name)
    except InvalidParameterError as err:
        raise InvalidParameterError(f"estimators.{_key(name)}", name, err.rule) from None


def _checked_options(scenario: Scenario, options) -> dict:
    """Validate ``[estimators.NAME]`` options by building each estimator from the scenario."""
    if not isinstance(options, dict):
        raise InvalidParameterError("estimator_options", options,
                                    "must map estimator names to their settings")
    checked = {}
    for name, settings in options.items():
        cls = _estimator_class(name)
        if not isinstance(settings, dict):
            raise InvalidParameterError(f"estimators.{_key(name)}", settings,
                                        "must be a section of settings")
        known = cls.option_names()
        for item, value in settings.items():
            if item in cls.owned_fields:
                raise InvalidParameterError(
                    f"estimators.{_key(name)}.{item}", _plain(value),
                    f"is the scenario setting {cls.scenario_defaults[item]}; set that instead")
            if item not in known:
                raise InvalidParameterError(
                    f"estimators.{_key(name)}.{item}", _plain(value),
                    f"is not a setting of {name}; known: {', '.join(known)}")
        checked[name] = dict(settings)
    for name in checked:
        try:
            _estimator_class(name).from_scenario(_OptionsView(scenario, checked))
        except InvalidParameterError as err:
            if err.name in checked[name]:
                raise InvalidParameterError(f"estimators.{_key(name)}.{err.name}", err.value,
                                            err.rule) from None
            raise
    return checked


class _OptionsView:
    """The scenario as an estimator's ``from_scenario`` sees it, with options
    not yet stored (the scenario is frozen while it validates itself)."""

    def __init__(self, scenario: Scenario, options: dict):
        self._scenario = scenario
        self.estimator_options = options

    def __getattr__(self, name):
        return getattr(self._scenario, name)
