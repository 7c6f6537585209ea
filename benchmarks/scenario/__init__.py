"""Scenarios: every setting of a run, validated where it enters.

:class:`Scenario` holds the workshop's defaults ("Default parameters"), so
``Scenario()`` is the workshop exercise, and the settings that go beyond it:
the gyro's bias model (:mod:`sensors.gyro`), the rotation-noise star tracker
(:mod:`sensors.star_tracker`), the vector sensors, an orbit or a ground site,
and each estimator's own options.

The package, in the order a newcomer may read it:

- here, :class:`Scenario`: what a scenario is, field by field;
- :mod:`.settings`: each setting declared once (:data:`SETTINGS`: its field,
  its section and key in a file, its unit and meaning), and the reading of
  files: the workshop's flat keys (the field names), sections, or both;
- :mod:`.sections`: a scenario read section by section, as the file writes it
  (``scenario.gyro.arw_deg_per_rthr``, ``scenario.magnetometer.sigma_nT``);
- :mod:`.checks`: the checks a scenario makes of itself on construction;
- :mod:`.builders`: the sensors, the orbit and the time zero it describes.

Load a file, then override field by field::

    scenario = Scenario.from_toml("scenarios/default.toml").replace(gyro_noise=1e-4)

A bad value raises :class:`~dynamics.validation.InvalidParameterError` (a
``ValueError``) whose message names the parameter, the value and the rule.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from benchmarks.scenario import builders
from benchmarks.scenario.checks import (
    MAX_GYRO_NOISE_RADPS, MAX_RATE_RADPS, MAX_STAR_NOISE, MAX_STEPS, ORBIT_CHECK_STEPS,
    STAR_TRACKER_MODELS, check_environment, check_estimator_fields, check_run_and_truth,
    check_sensors, derive_estimator_fields, site_coordinates, warn_of_idle_sensors)
from benchmarks.scenario.sections import add_section_views, field_changes
from benchmarks.scenario.settings import (
    CIRCULAR_ORBIT_FIELDS, DATASHEET_KEYS, SECTIONS, SETTINGS, SWITCHES, WORKSHOP_FIELDS,
    SectionKey, Setting, allowed_modules, check_import_consent, estimator_sections,
    flatten_sections, layered_settings, plain_value, read_toml)
from sensors.star_tracker import on_gyro_grid
from sensors.sun_sensor import CUBE_FACES

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
    """All settings of one run: the truth, the sensors, where they are (an
    orbit or a ground site) and the estimators' own; the defaults are the
    workshop's. SI units and radians unless a field's name says otherwise.

    Each field is a setting of :data:`SETTINGS`, which declares where a file
    sets it, its unit and its meaning (all printed, with these defaults, by
    ``attitude-bench show-config --keys``); read them by section as the file
    writes them: ``scenario.gyro.arw_deg_per_rthr`` (:mod:`.sections`). None
    means:

    * for ``pc_exponent``, ``measurement_covariance``, ``initial_covariance``
      (the EKF's): derived from the sensors, the workshop's values on the
      workshop's (:meth:`estimators.QuaternionEKF.derived_fields`);
      ``derived_fields`` names those that were; :meth:`replace` derives them anew;
    * for ``epoch``: the element set's with an ``orbit_tle``, else
      :data:`dynamics.orbit.DEFAULT_EPOCH` (:attr:`epoch_moment`);
    * for ``orbit_altitude_km`` (and no ``orbit_tle``), ``site_latitude_deg``
      and a vector sensor's interval: no orbit, no ground site, no such sensor.

    ``estimator_options``: ``{estimator name: {keyword: value}}``, the other
    keys of the ``[estimators.NAME]`` sections
    (:meth:`estimators.AttitudeEstimator.from_scenario`).
    """

    # The workshop's settings, in its order (WORKSHOP_FIELDS).
    tstop: float = 50.0
    dt: float = 0.01                                    # 100 Hz
    inertia_tensor_kg_m2: np.ndarray = _diag(1.0, 2.0, 3.0)           # 3 numbers: a diagonal
    initial_attitude_quat: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)   # scalar-first
    initial_rate_radps: np.ndarray = _vector(0.05, 0.05, 0.0)
    gyro_noise: float = 1e-5                            # σ_v²: angle random walk density²
    star_tracker_noise: float = 1e-6
    time_between_measurements: float = 0.2              # off the gyro's grid: own times
    pc_exponent: float | None = None
    measurement_covariance: np.ndarray | None = None    # a number: that times I₄
    initial_state: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    initial_covariance: float | None = None
    # Beyond the workshop, section by section.
    gyro_bias_random_walk: float = 0.0                  # [gyro]
    gyro_initial_bias_radps: np.ndarray = _vector(0.0, 0.0, 0.0)
    gyro_scale_misalignment: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    gyro_sampling: str = "sample"
    gyro_bias_instability_radps: float = 0.0
    gyro_bias_correlation_time_s: float = 3600.0
    star_tracker_model: str = "workshop"                # [star_tracker]: STAR_TRACKER_MODELS
    star_tracker_sigma_arcsec: np.ndarray = _vector(6.0, 6.0, 40.0)   # x, y across boresight
    star_tracker_dropout_probability: float = 0.0
    star_tracker_outages_s: tuple = ()                  # ((start, stop), ...)
    star_tracker_sign: str = "raw"                      # canonical: w >= 0
    star_tracker_to_body_quat: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    epoch: str | None = None                            # [environment]: ISO 8601 UTC
    magnetic_field_model: str = "igrf"
    shadow_model: str = "conical"
    orbit_altitude_km: float | None = None              # [orbit]: circular, or an orbit_tle
    orbit_inclination_deg: float = 97.4
    orbit_raan_deg: float = 0.0
    orbit_argument_of_latitude_deg: float = 0.0
    orbit_tle: tuple = ()
    site_latitude_deg: float | None = None              # [site]: frame east-north-up there
    site_longitude_deg: float = 0.0
    site_altitude_km: float = 0.0
    magnetometer_interval_s: float | None = None        # [magnetometer]
    magnetometer_sigma_nT: float = 100.0
    magnetometer_bias_nT: np.ndarray = _vector(0.0, 0.0, 0.0)
    magnetometer_soft_iron: np.ndarray = _diag(1.0, 1.0, 1.0)
    sun_sensor_interval_s: float | None = None          # [sun_sensor]
    sun_sensor_sigma_deg: float = 0.1
    sun_sensor_fov_deg: float = 70.0
    sun_sensor_boresight: np.ndarray = _vector(0.0, 0.0, 1.0)
    coarse_sun_interval_s: float | None = None          # [coarse_sun_sensors]
    coarse_sun_sigma: float = 0.01
    coarse_sun_normals: np.ndarray = field(default_factory=lambda: np.array(CUBE_FACES))
    accelerometer_interval_s: float | None = None       # [accelerometer]
    accelerometer_sigma_mps2: float = 0.01
    accelerometer_bias_mps2: np.ndarray = _vector(0.0, 0.0, 0.0)
    estimator_options: dict = field(default_factory=dict)

    def __post_init__(self):
        # Each value checked, and stored as checked, in this order (.checks).
        check_run_and_truth(self)
        check_sensors(self)
        check_environment(self)
        warn_of_idle_sensors(self)          # its warning points here
        derive_estimator_fields(self)
        check_estimator_fields(self)

    def build_gyro(self):
        """The :class:`~sensors.gyro.Gyro` this scenario describes."""
        return builders.gyro(self)

    def build_star_tracker(self):
        """The star tracker this scenario describes (:mod:`sensors.star_tracker`)."""
        return builders.star_tracker(self)

    def build_vector_sensors(self) -> list:
        """The vector sensors this scenario has, in a fixed order
        (magnetometer, fine sun sensor, coarse sun sensors, accelerometer)."""
        return builders.vector_sensors(self)

    def build_orbit(self):
        """The :class:`~dynamics.orbit.CircularOrbit` or
        :class:`~dynamics.orbit.TLEOrbit` this scenario describes, or None."""
        return builders.orbit(self)

    @property
    def orbit_settings(self) -> dict:
        """The keywords of :func:`dynamics.orbit.make_orbit` (hashable values)."""
        return builders.orbit_settings(self)

    @property
    def epoch_moment(self):
        """Time zero as a UTC datetime: the given epoch, or the element set's,
        or :data:`dynamics.orbit.DEFAULT_EPOCH`."""
        return builders.epoch_moment(self)

    @property
    def site(self) -> tuple | None:
        """``(latitude_deg, longitude_deg, altitude_km)`` of a ground IMU, or None."""
        if self.site_latitude_deg is None:
            return None
        return site_coordinates(self.site_latitude_deg, self.site_longitude_deg,
                                self.site_altitude_km)

    @property
    def has_vector_sensors(self) -> bool:
        return any(getattr(self, name) is not None for name in (
            "magnetometer_interval_s", "sun_sensor_interval_s", "coarse_sun_interval_s",
            "accelerometer_interval_s"))

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
        """A copy with some fields changed (validated like the original), by
        field name or by a section's keys as the file writes them:
        ``replace(gyro={"arw_deg_per_rthr": 0.15})`` (:func:`field_changes`)."""
        changes = field_changes(changes, field_names())
        for name in self.derived_fields:
            changes.setdefault(name, None)       # derived again from the new sensors
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """Plain-Python values (lists for arrays and tuples), e.g. for JSON or TOML."""
        return {name: plain_value(getattr(self, name)) for name in field_names()}

    @classmethod
    def from_toml(cls, path, *, allow_imports=()) -> "Scenario":
        """Load a scenario file, or a list of files laid over each other in
        order (a later file's key overrides an earlier one's); missing keys
        take the defaults. A section ``[estimators."package.module:ClassName"]``
        is refused unless ``allow_imports`` names its module, for importing runs
        its code (:func:`~benchmarks.scenario.settings.layered_settings`)."""
        return cls().replace(**layered_settings(path, allow_imports))

    def with_estimator_settings(self, path, *, allow_imports=()) -> "Scenario":
        """This scenario with the ``[estimators.NAME]`` sections of the file
        ``path`` laid over it (for scenarios made otherwise, e.g. from a
        recording); any other key in the file is refused. ``allow_imports``
        as for :meth:`from_toml`."""
        return self.replace(**estimator_sections(path, allow_imports, self.estimator_options))


#: Sections left without a view: ``Scenario.site`` is already the ground
#: site's ``(latitude_deg, longitude_deg, altitude_km)``, read across the project.
UNVIEWED_SECTIONS = ("site",)
add_section_views(Scenario, leave_out=UNVIEWED_SECTIONS)


def field_names() -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(Scenario))
