"""Scenarios: every setting of a run, validated where it enters.

:class:`Scenario` holds the workshop's defaults ("Default parameters"), so
``Scenario()`` is the workshop exercise, and the settings that go beyond it:
the gyro's bias model (:mod:`sensors.gyro`), the rotation-noise star tracker
(:mod:`sensors.star_tracker`), and each estimator's own options.

Its settings are declared once, with the sections and keys of a scenario
file, in :mod:`benchmarks.scenario.settings` (:data:`SETTINGS`), which also
reads the files: the workshop's flat keys (the field names), sections, or
both. Load one, then override field by field::

    scenario = Scenario.from_toml("scenarios/default.toml").replace(gyro_noise=1e-4)

and read it as the file writes it, section by section (:mod:`.sections`):
``scenario.gyro.arw_deg_per_rthr``, ``scenario.magnetometer.sigma_nT``.

Every value is checked on construction (one value at a time here, the rest
in :mod:`benchmarks.scenario.checks`); a bad one raises
:class:`~dynamics.validation.InvalidParameterError` (a ``ValueError``) whose
message names the parameter, the value and the rule.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from benchmarks.scenario.checks import (
    MAX_GYRO_NOISE_RADPS, MAX_RATE_RADPS, MAX_STAR_NOISE, MAX_STEPS, ORBIT_CHECK_STEPS,
    STAR_TRACKER_MODELS, check_body_rate, check_gyro_noise, check_places, check_run_length,
    check_standard_deviations, check_star_tracker_noise, checked_options, site_coordinates,
    warn_of_idle_sensors)
from benchmarks.scenario.sections import add_section_views
from benchmarks.scenario.settings import (
    CIRCULAR_ORBIT_FIELDS, DATASHEET_KEYS, SECTIONS, SETTINGS, SWITCHES, WORKSHOP_FIELDS,
    SectionKey, Setting, allowed_modules, check_import_consent, estimator_sections,
    flatten_sections, layered_settings, plain_value, read_toml)
from dynamics.validation import (InvalidParameterError, covariance_matrix, finite_number,
                                 finite_vector, inertia_tensor, nonzero_quaternion, one_of,
                                 process_exponent)
from dynamics.environment import FIELD_MODELS, SHADOW_MODELS
from dynamics.orbit import DEFAULT_EPOCH, TLEOrbit, epoch_datetime, make_orbit, tle_lines
from estimators import ESTIMATORS
from sensors.accelerometer import Accelerometer
from sensors.gyro import Gyro
from sensors.magnetometer import Magnetometer
from sensors.star_tracker import (NoStarTracker, RotationStarTracker, StarTracker, on_gyro_grid,
                                  outage_windows, reading_interval)
from sensors.sun_sensor import CUBE_FACES, CoarseSunSensors, FineSunSensor

#: What ``from benchmarks.scenario import …`` offers: the scenario, and its
#: settings' declaration and files (:mod:`.settings`) and limits (:mod:`.checks`).
__all__ = [
    "Scenario", "field_names", "UNVIEWED_SECTIONS", "CIRCULAR_ORBIT_FIELDS", "DATASHEET_KEYS",
    "SECTIONS", "SETTINGS", "SWITCHES", "WORKSHOP_FIELDS", "SectionKey", "Setting",
    "allowed_modules", "check_import_consent", "flatten_sections", "read_toml",
    "MAX_GYRO_NOISE_RADPS", "MAX_RATE_RADPS", "MAX_STAR_NOISE", "MAX_STEPS", "ORBIT_CHECK_STEPS",
    "STAR_TRACKER_MODELS"]


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
        self._check_run_and_truth()
        self._check_sensors()
        self._check_environment()
        warn_of_idle_sensors(self)
        self._derive_estimator_fields()
        self._check_estimator_fields()

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)       # the dataclass is frozen

    def _check_run_and_truth(self) -> None:
        """The time grid, and the truth's initial state."""
        self._set("dt", finite_number("dt", self.dt, strictly_positive=True))
        self._set("tstop", finite_number("tstop", self.tstop, strictly_positive=True))
        check_run_length(self.tstop, self.dt)
        self._set("inertia_tensor_kg_m2", inertia_tensor("inertia_tensor_kg_m2",
                                                         self.inertia_tensor_kg_m2))
        self._set("initial_attitude_quat", nonzero_quaternion("initial_attitude_quat",
                                                              self.initial_attitude_quat))
        self._set("initial_rate_radps", finite_vector("initial_rate_radps",
                                                      self.initial_rate_radps, 3))
        check_body_rate(self.initial_rate_radps)

    def _check_sensors(self) -> None:
        """The gyro and the star tracker: their noise, interval and model
        here, the rest normalised by their own classes."""
        set_ = self._set
        set_("gyro_noise", finite_number("gyro_noise", self.gyro_noise, minimum=0.0))
        check_gyro_noise(self.gyro_noise, self.dt)
        set_("star_tracker_noise", finite_number("star_tracker_noise", self.star_tracker_noise,
                                                 minimum=0.0))
        check_star_tracker_noise(self.star_tracker_noise, self.dt)
        set_("time_between_measurements", reading_interval(self.time_between_measurements,
                                                           self.dt))
        set_("initial_state", nonzero_quaternion("initial_state", self.initial_state))
        one_of("star_tracker_model", self.star_tracker_model, STAR_TRACKER_MODELS)
        set_("star_tracker_outages_s", outage_windows("star_tracker_outages_s",
                                                      self.star_tracker_outages_s))
        check_standard_deviations(self)
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

    def _check_environment(self) -> None:
        """The epoch and the environment's models; then the orbit, the site
        and the vector sensors (:func:`~benchmarks.scenario.checks.check_places`)."""
        if self.epoch is not None:
            self._set("epoch", epoch_datetime("environment.epoch", self.epoch).isoformat())
        one_of("environment.magnetic_field_model", self.magnetic_field_model, FIELD_MODELS)
        one_of("environment.shadow_model", self.shadow_model, SHADOW_MODELS)
        self._set("orbit_tle", tle_lines("orbit.tle", self.orbit_tle))
        check_places(self)

    def _check_estimator_fields(self) -> None:
        """The estimators' own fields, derived or given, and their options."""
        set_ = self._set
        set_("pc_exponent", process_exponent("pc_exponent", self.pc_exponent))
        set_("measurement_covariance", covariance_matrix("measurement_covariance",
                                                         self.measurement_covariance))
        set_("initial_covariance", finite_number("initial_covariance", self.initial_covariance,
                                                 strictly_positive=True))
        set_("estimator_options", checked_options(self, self.estimator_options))

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
        return site_coordinates(self.site_latitude_deg, self.site_longitude_deg,
                                self.site_altitude_km)

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
        return {name: plain_value(getattr(self, name)) for name in field_names()}

    @classmethod
    def from_toml(cls, path, *, allow_imports=()) -> "Scenario":
        """Load a scenario file: flat field names and/or sections (see
        :mod:`benchmarks.scenario.settings`); missing keys take the defaults.

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
        return cls().replace(**layered_settings(path, allow_imports))

    def with_estimator_settings(self, path, *, allow_imports=()) -> "Scenario":
        """This scenario with the ``[estimators.NAME]`` sections of the file
        ``path`` laid over it (for scenarios made otherwise, e.g. from a
        recording); any other key in the file is refused. ``allow_imports``
        as for :meth:`from_toml`."""
        flat = estimator_sections(path, allow_imports)
        options = {name: dict(settings) for name, settings in self.estimator_options.items()}
        for name, settings in flat.pop("estimator_options", {}).items():
            options.setdefault(name, {}).update(settings)
        return self.replace(**flat, estimator_options=options)


#: Sections left without a view: ``Scenario.site`` is already the ground
#: site's ``(latitude_deg, longitude_deg, altitude_km)``, read across the project.
UNVIEWED_SECTIONS = ("site",)
add_section_views(Scenario, leave_out=UNVIEWED_SECTIONS)


def field_names() -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(Scenario))
