"""An estimator's settings: where each comes from, and the checks they share.

An estimator takes keyword-only settings. Built from a scenario
(:meth:`SettingsFromScenario.from_scenario`), each setting comes from the
first of these that gives it: the ``overrides``; the scenario's
``[estimators.NAME]`` section (:meth:`~SettingsFromScenario.scenario_section`);
the scenario's fields named by ``scenario_defaults``, or derived from its
sensor models (:meth:`~SettingsFromScenario.settings_from_scenario`); the
constructor's own defaults (:meth:`~SettingsFromScenario.constructor_defaults`). The
scenario is duck-typed: this package never imports ``benchmarks``.

Also here: the choices every estimator's ``on_invalid`` and every filter's
``output`` take (:data:`ON_INVALID`, :data:`OUTPUTS`), and the check of
per-axis standard deviations (:func:`axis_sigmas`). The gate's settings are
checked beside the gate, in :mod:`estimators.gating`.
"""
from __future__ import annotations

import inspect
import sys
from typing import Self

import numpy as np

from dynamics.validation import axis_standard_deviations

#: What an estimator does with a measurement that cannot be used (a
#: non-finite rate, a non-finite or zero reading).
ON_INVALID = ("raise", "skip")
#: Which estimate a filter's step returns: before or after that step's reading.
OUTPUTS = ("prior", "posterior")
#: The constructors' defaults, where neither a scenario nor the caller gives
#: a setting (the workshop's: :class:`benchmarks.scenario.Scenario`): the
#: gyro's step (100 Hz), its angle random walk's density σ_v² (rad²/s), and
#: the filters' tracker variance per axis and priors on the attitude (rad)
#: and on the bias (rad/s).
DEFAULT_DT_S = 0.01
DEFAULT_GYRO_NOISE = 1e-5
DEFAULT_MEASUREMENT_COVARIANCE = 1e-4
DEFAULT_ATTITUDE_SIGMA_RAD = 0.1
DEFAULT_BIAS_SIGMA_RADPS = 1e-4


class SettingsFromScenario:
    """How an estimator class is configured from a scenario (mixed into
    :class:`~estimators.base.AttitudeEstimator`, whose ``name``,
    ``scenario_defaults`` and ``__init__`` these read)."""

    @classmethod
    def derived_fields(cls, scenario) -> dict:
        """Values of this estimator's :attr:`owned_fields` (by scenario field
        name) that a scenario leaves unset, derived from its sensors (the
        scenario is complete but for these)."""
        return {}

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """Constructor keywords taken from ``scenario`` before its
        ``[estimators.NAME]`` options (override to derive more, e.g. noise
        densities from the sensor models)."""
        settings = {"dt": scenario.dt}
        settings.update({keyword: getattr(scenario, field)
                         for keyword, field in cls.scenario_defaults.items()})
        return settings

    @classmethod
    def constructor_defaults(cls) -> dict:
        """The constructor's own defaults of its keyword-only settings."""
        return {name: parameter.default for name, parameter in
                inspect.signature(cls.__init__).parameters.items()
                if parameter.kind is inspect.Parameter.KEYWORD_ONLY
                and parameter.default is not inspect.Parameter.empty}

    @classmethod
    def configured_settings(cls, scenario) -> dict:
        """The constructor keywords ``scenario`` gives: its defaults for this
        estimator, then its ``[estimators.NAME]`` section."""
        settings = cls.settings_from_scenario(scenario)
        settings.update(cls.scenario_section(scenario))
        return settings

    @classmethod
    def from_scenario(cls, scenario, **overrides) -> Self:
        """This estimator as ``scenario`` configures it (``overrides`` last)."""
        settings = cls.configured_settings(scenario)
        settings.update(overrides)
        return cls(**settings)

    @classmethod
    def scenario_section(cls, scenario) -> dict:
        """This estimator's ``[estimators.NAME]`` section of ``scenario``: a
        registry class's under its :attr:`name`, a user's under its
        ``"package.module:ClassName"`` spec (so the Python API applies the
        same section the command line does)."""
        options = getattr(scenario, "estimator_options", {}) or {}
        # A registry name's section is the registry class's (and its subclasses'),
        # never a user's class that happens to share its name.
        section = dict(options.get(cls.name, {})) if _registry_class(cls) is not None else {}
        for key, values in options.items():
            module_name, colon, class_name = key.partition(":")
            module = sys.modules.get(module_name) if colon else None
            if module is not None and getattr(module, class_name, None) is cls:
                section.update(values)
        return section

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """The settings an ``[estimators.NAME]`` section may give: the
        constructor's keyword-only arguments but ``dt`` (the scenario's)."""
        return tuple(name for name, parameter in inspect.signature(cls.__init__).parameters.items()
                     if parameter.kind is inspect.Parameter.KEYWORD_ONLY and name != "dt")


def _registry_class(cls):
    """The class of this package that gave ``cls`` its name — a registry
    estimator, ``cls`` itself or one it derives from — or None: a user's
    class that only shares a registry name. (Found by where the name was
    declared, not by importing the registry, which imports this package's
    base.) The class these settings are mixed into,
    :class:`~estimators.base.AttitudeEstimator`, is none: its ``name`` is a
    placeholder."""
    return next((klass for klass in cls.__mro__
                 if SettingsFromScenario not in klass.__bases__ and "name" in vars(klass)
                 and klass.name == cls.name
                 and klass.__module__.partition(".")[0] == __name__.partition(".")[0]), None)


def axis_sigmas(name: str, value) -> np.ndarray:
    """One standard deviation per axis (a number means the same on all three),
    >= 0 and small enough that its square (a variance) is finite."""
    return axis_standard_deviations(name, value)
