r"""Tunable settings: which of an estimator's settings a tuner may vary, over
what range and on what scale.

An estimator class declares them in its :attr:`~estimators.AttitudeEstimator.tunable`
tuple, one :class:`Tunable` each, named as its constructor keyword (so a
tuned value is an ``[estimators.NAME]`` key, reusable in a scenario file):

>>> from estimators import MultiplicativeEKF
>>> [t.name for t in MultiplicativeEKF.tunable]  # doctest: +NORMALIZE_WHITESPACE
['gyro_noise', 'gyro_bias_random_walk', 'measurement_scale', 'gate_probability',
 'magnetic_norm_tolerance', 'gravity_density', 'heading_density']

A user's class declares its own the same way. The *default* of a setting is
the value the estimator takes from the scenario (``from_scenario``, with
the scenario's ``[estimators.NAME]`` section), so a search starts from what
the user would run. Its search range is ``span`` decades either side of it
(log scale) or ``span`` units (linear), unless :attr:`Tunable.search` fixes
it, and always within :attr:`Tunable.limits`, the values the setting
accepts. A *scale* setting (``scales``) multiplies another: the
``measurement_scale`` of a filter multiplies its measurement covariance, a
matrix, by one number.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynamics.validation import InvalidParameterError

SCALES = ("log", "linear", "log-complement")


@dataclass(frozen=True)
class Tunable:
    """One tunable setting.

    Attributes
    ----------
    name : str
        The constructor keyword (or, with ``scales``, the name of the factor).
    scale : {"log", "linear", "log-complement"}
        The tuner searches ``log10(value)``, ``value``, or ``log10(1 − value)``
        (a probability near 1: 0.99, 0.999 and 0.9999 a step apart).
    limits : (low, high)
        The values the setting accepts (inclusive); a range asked for must
        lie within them.
    span : float
        The default search range: decades (log) or units (linear) either
        side of the default.
    scales : str or None
        The keyword this factor multiplies (its default is 1).
    search : (low, high) or None
        A fixed default search range, for a setting that may have no default
        (e.g. a gate that is off).
    description : str
    sensor : str or None
        The one sensor whose readings it acts on (:mod:`estimators.sensing`'s
        names): on data without that sensor it changes nothing, and is not
        tuned. None: it acts on every reading.
    applies_when : (keyword, value) or None
        The estimator's setting it acts under (an IMU model's density acts
        only where that model is on); None: always.
    """

    name: str
    scale: str
    limits: tuple
    span: float = 2.0
    scales: str | None = None
    search: tuple | None = None
    description: str = ""
    sensor: str | None = None
    applies_when: tuple | None = None

    def acts(self, settings: dict) -> bool:
        """Whether it acts on an estimator of ``settings`` (:attr:`applies_when`)."""
        return self.applies_when is None or \
            settings.get(self.applies_when[0]) == self.applies_when[1]

    def coordinate(self, value: float) -> float:
        """The tuner's coordinate of ``value``."""
        if self.scale == "log":
            return math.log10(value)
        if self.scale == "log-complement":
            return math.log10(1.0 - value)
        return float(value)

    def value(self, coordinate: float) -> float:
        """The setting's value at the tuner's ``coordinate``, within the limits."""
        if self.scale == "log":
            value = 10.0 ** coordinate
        elif self.scale == "log-complement":
            value = 1.0 - 10.0 ** coordinate
        else:
            value = float(coordinate)
        return min(max(value, self.limits[0]), self.limits[1])

    def default(self, settings: dict) -> float | None:
        """The default value in an estimator's ``settings`` (None: there is none)."""
        if self.scales is not None:
            return 1.0
        value = settings.get(self.name)
        return None if value is None else float(value)

    def search_range(self, default: float | None) -> tuple[float, float]:
        """The default search range around ``default``, within the limits."""
        if self.search is not None:
            return self.search
        if default is None or (self.scale == "log" and not default > 0):
            raise InvalidParameterError(self.name, default, "has no default to search around "
                                        "(none, or 0 on a log scale): give its range, "
                                        f"e.g. --range {self.name}=LO:HI")
        if self.scale == "log":
            low, high = default / 10.0 ** self.span, default * 10.0 ** self.span
        else:
            low, high = default - self.span, default + self.span
        return max(low, self.limits[0]), min(high, self.limits[1])

    def checked_range(self, low: float, high: float) -> tuple[float, float]:
        """A range a user asked for: ``low < high``, both within the limits."""
        if not (math.isfinite(low) and math.isfinite(high)) or not low < high:
            raise InvalidParameterError(f"range of {self.name}", [low, high],
                                        "must be LO:HI with LO < HI, both finite")
        if low < self.limits[0] or high > self.limits[1]:
            raise InvalidParameterError(f"range of {self.name}", [low, high],
                                        f"must lie within its declared limits "
                                        f"[{self.limits[0]:g}, {self.limits[1]:g}]")
        return float(low), float(high)

    def overrides(self, value: float, settings: dict) -> dict:
        """The constructor keywords that set this setting to ``value``."""
        if self.scales is None:
            return {self.name: value}
        return {self.scales: value * np.asarray(settings[self.scales], dtype=float)}


def tunables(estimator_class) -> dict:
    """``name → Tunable`` of what ``estimator_class`` declares."""
    return {t.name: t for t in getattr(estimator_class, "tunable", ())}


#: What the filters that share a gyro model declare (the MEKF and USQUE).
GYRO_NOISE = Tunable("gyro_noise", "log", (1e-30, 1e6), span=3.0,
                     description="σ_v², the gyro's angle-random-walk power (rad²/s)")
GYRO_BIAS_RANDOM_WALK = Tunable("gyro_bias_random_walk", "log", (1e-20, 1e3), span=3.0,
                                description="σ_u, the bias's rate random walk (rad/s^1.5)")
MEASUREMENT_SCALE = Tunable("measurement_scale", "log", (1e-12, 1e12), span=3.0,
                            scales="measurement_covariance",
                            description="a factor on the star tracker's covariance R",
                            sensor="star_tracker")
GATE_PROBABILITY = Tunable("gate_probability", "log-complement", (1e-6, 1.0 - 1e-12),
                           search=(0.9, 0.999999),
                           description="the χ² probability of innovation gating")
MAGNETIC_NORM_TOLERANCE = Tunable("magnetic_norm_tolerance", "log", (1e-6, 1e3),
                                  search=(0.01, 1.0),
                                  description="the magnetic disturbance test's tolerance on "
                                  "the field's magnitude (a fraction)", sensor="magnetometer")
#: The IMU models' densities (:mod:`estimators.imu`), tuned only when named:
#: they act only where the filter's settings turn the models on.
GRAVITY_DENSITY = Tunable("gravity_density", "log", (1e-16, 1.0), search=(1e-8, 1e-3),
                          description="the low-passed gravity direction's error density "
                          "(rad²·s)", sensor="accelerometer",
                          applies_when=("gravity_model", "lowpass"))
HEADING_DENSITY = Tunable("heading_density", "log", (1e-16, 1.0), search=(1e-6, 1e-1),
                          description="the heading-only magnetometer's error density (rad²·s)",
                          sensor="magnetometer", applies_when=("magnetometer_model", "heading"))
#: A static solver's weight on the magnetometer against the other sensors.
MAGNETOMETER_WEIGHT = Tunable("magnetometer_weight", "log", (1e-9, 1e9), search=(1e-3, 1e3),
                              description="a factor on the magnetometer's weight σ⁻² in "
                              "Wahba's loss", sensor="magnetometer")
