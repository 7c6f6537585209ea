"""A scenario's settings, declared once, and the files that give them.

Each setting of a :class:`~benchmarks.scenario.Scenario` is declared once in
:data:`SETTINGS`: its field, where a TOML file sets it, its unit and meaning,
its command-line flag, and whether a batch or ``sweep`` may vary it. The
file's sections (:data:`SECTIONS`), the flags and the sweepable parameters are
made from that table.

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
rather than silently ignored. Files may be laid over each other
(:func:`layered_settings`); reading one never imports a module the caller
did not consent to (:func:`check_import_consent`).
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynamics.validation import MISSING, InvalidParameterError, finite_vector, standard_deviation
from estimators import ESTIMATORS, resolve_estimator
from sensors.noise import (arw_deg_per_rthr_to_rad_per_rts, arw_rad_per_rts_to_deg_per_rthr,
                           bias_instability_deg_per_hr_to_radps, deg_per_hr_to_radps,
                           noise_density_deg_per_s_rthz_to_rad_per_rts, radps_to_deg_per_hr,
                           rrw_deg_per_hr_rthr_to_rad_per_s1p5, rrw_rad_per_s1p5_to_deg_per_hr_rthr)


@dataclass(frozen=True)
class SectionKey:
    """A key of a TOML section: the field it sets, for datasheet units the
    conversion to the field's SI unit and back (``read_back``, for a
    scenario read by sections: :mod:`benchmarks.scenario.sections`), and
    whether ``sweep`` can vary it (``--param SECTION.KEY``, one number per
    run; for a per-axis σ, a number is the same σ on every axis)."""

    field: str
    convert: object = None
    sweepable: bool = False
    read_back: object = None


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

#: The workshop's own settings: the keys of ``scenarios/default.toml``.
WORKSHOP_FIELDS = ("tstop", "dt", "inertia_tensor_kg_m2", "initial_attitude_quat",
                   "initial_rate_radps", "gyro_noise", "star_tracker_noise",
                   "time_between_measurements", "pc_exponent", "measurement_covariance",
                   "initial_state", "initial_covariance")

#: Keys in datasheet units: section → key → the setting's field, the
#: conversion to it and the one back from it.
DATASHEET_KEYS = {
    "gyro": {
        "arw_deg_per_rthr": SectionKey(
            "gyro_noise", lambda v: arw_deg_per_rthr_to_rad_per_rts(
                standard_deviation("gyro.arw_deg_per_rthr", v)) ** 2, sweepable=True,
            read_back=lambda p: arw_rad_per_rts_to_deg_per_rthr(math.sqrt(p))),
        "bias_rw_deg_per_hr_rthr": SectionKey(
            "gyro_bias_random_walk", lambda v: rrw_deg_per_hr_rthr_to_rad_per_s1p5(
                standard_deviation("gyro.bias_rw_deg_per_hr_rthr", v)), sweepable=True,
            read_back=rrw_rad_per_s1p5_to_deg_per_hr_rthr),
        "noise_density_deg_per_s_rthz": SectionKey(
            "gyro_noise", lambda v: noise_density_deg_per_s_rthz_to_rad_per_rts(
                standard_deviation("gyro.noise_density_deg_per_s_rthz", v)) ** 2,
            sweepable=True, read_back=lambda p: math.degrees(math.sqrt(p))),   # 1/√Hz = √s
        "bias_instability_deg_per_hr": SectionKey(
            "gyro_bias_instability_radps", lambda v: bias_instability_deg_per_hr_to_radps(
                standard_deviation("gyro.bias_instability_deg_per_hr", v)), sweepable=True,
            read_back=radps_to_deg_per_hr),
        "initial_bias_deg_per_hr": SectionKey(
            "gyro_initial_bias_radps", lambda v: deg_per_hr_to_radps(
                finite_vector("gyro.initial_bias_deg_per_hr", v, 3)),
            read_back=radps_to_deg_per_hr),
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

#: The sections that are off unless a key switches them on: that key (for
#: [orbit], either of two). A section given without it is refused.
SWITCHES = {"orbit": ("altitude_km", "tle"), "site": ("latitude_deg",),
            "magnetometer": ("interval_s",), "sun_sensor": ("interval_s",),
            "coarse_sun_sensors": ("interval_s",), "accelerometer": ("interval_s",)}
#: A circular orbit's settings: none of them may stand beside an element set.
CIRCULAR_ORBIT_FIELDS = ("orbit_altitude_km", "orbit_inclination_deg", "orbit_raan_deg",
                         "orbit_argument_of_latitude_deg")


def plain_value(value):
    """``value`` in plain Python: lists for arrays and tuples (e.g. for JSON or TOML)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return [plain_value(item) for item in value]
    if isinstance(value, dict):
        return {key: plain_value(item) for key, item in value.items()}
    return value


def toml_key(name: str) -> str:
    """``name`` as a TOML key: bare if it can be, quoted otherwise."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else f'"{name}"'


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
            f"estimators.{toml_key(name)}", plain_value(settings),
            f"reading the file would import {module} and run its code; allow it with "
            f"--allow-import {module} or by naming {name} in --estimators (from Python: "
            f"allow_imports=[{module!r}])")


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
            raise InvalidParameterError(where, plain_value(value), f"sets {field_name}, which "
                                        "another key already sets")
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
                cls = estimator_class(name)
                for item, item_value in settings.items():
                    if item in cls.owned_fields:
                        put(cls.scenario_defaults[item], item_value,
                            f"estimators.{toml_key(name)}.{item}")
                    else:
                        options.setdefault(name, {})[item] = item_value
        else:
            put(key, value, key)
    if options:
        put("estimator_options", options, "estimators")
    return flat


def layered_settings(path, allow_imports=()) -> dict:
    """The field values of the scenario file ``path`` (:meth:`Scenario.from_toml`),
    with ``estimator_options`` if it gives ``[estimators.NAME]`` options;
    missing keys are left out (the scenario's defaults).

    ``path`` may be a list of files, laid over each other in order: a later
    file's setting overrides an earlier one's key by key (in any of its
    units), and its ``[estimators.NAME]`` keys override those of the same
    section. So a change to try is a small file over the full one. A layer
    may also be a file's document already read (the command line's ``--set``).

    A section ``[estimators."package.module:ClassName"]`` imports that module,
    which runs its code: it is refused, before anything is imported, unless
    ``allow_imports`` (module names, or ``package.module:ClassName`` specs,
    which allow their module) names the module (:func:`check_import_consent`).
    Registry names (``[estimators.mekf]``) need no consent.
    """
    paths = [path] if isinstance(path, (str, Path)) else list(path)
    if not paths:
        raise InvalidParameterError("scenario", paths, "must name at least one file")
    flat, options, present = {}, {}, {}
    for each in paths:
        data = each if isinstance(each, dict) else read_toml(each)   # a dict: a file's document
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
    return {**flat, **({"estimator_options": options} if options else {})}


def estimator_sections(path, allow_imports=(), options=None) -> dict:
    """The field values of a file that gives ``[estimators.NAME]`` sections
    only (:meth:`Scenario.with_estimator_settings`); any other key is refused.
    Its ``estimator_options`` are the file's laid over ``options`` (a scenario's),
    section by section."""
    data = read_toml(path)
    check_import_consent(data, allow_imports)
    for key, value in data.items():
        if key != "estimators":
            raise InvalidParameterError(key, plain_value(value), "only [estimators.NAME] "
                                        "sections may be given here; the rest is set "
                                        "for you")
    flat = flatten_sections(data)
    laid = {name: dict(settings) for name, settings in (options or {}).items()}
    for name, settings in flat.pop("estimator_options", {}).items():
        laid.setdefault(name, {}).update(settings)
    return {**flat, "estimator_options": laid}


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
                    f"orbit.{key}", plain_value(flat[name]), "is a circular orbit's setting, "
                    "and orbit.tle is given: an element set carries its own orbit; give one or "
                    "the other")


def estimator_class(name: str):
    """The class of an ``[estimators.NAME]`` section: a registry name, or a
    user's own as ``[estimators."package.module:ClassName"]``."""
    if name in ESTIMATORS:
        return ESTIMATORS[name]
    if ":" not in name:
        raise InvalidParameterError(f"estimators.{toml_key(name)}", name,
                                    f"is not an estimator; known: {', '.join(ESTIMATORS)}, "
                                    "or \"package.module:ClassName\" for your own")
    try:
        return resolve_estimator(name)
    except InvalidParameterError as err:
        raise InvalidParameterError(f"estimators.{toml_key(name)}", name, err.rule) from None
