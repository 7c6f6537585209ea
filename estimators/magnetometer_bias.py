r"""The MEKF's magnetometer bias (hard-iron) states: their settings and bookkeeping.

With ``magnetometer_bias_states`` the MEKF (:mod:`estimators.mekf`, whose
docstring gives the model) estimates the magnetometer's hard iron
:math:`b_m` as three more error states after its six,
:math:`\Delta x = [\delta\theta, \Delta\beta, \Delta b_m]`, constant, with a
prior of ``initial_magnetometer_bias_sigma`` per axis (Lefferts, Markley &
Shuster 1982; Markley & Crassidis 2014, §6.2). The filter's equations stay
in its class; here is what the states need around them:
:class:`MagnetometerBiasStates` derives them from a scenario that declares a
hard iron, validates their settings, grows the initial covariance by their
prior, and says which readings carry the hard iron, whose norm test then
reads the field less its estimate; :func:`estimates_hard_iron` tells the
engine whether a filter's settings turn them on.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from dynamics.validation import InvalidParameterError, boolean
from estimators import sensing
from estimators.settings import axis_sigmas

#: The error states of the attitude and the gyro bias; the magnetometer's
#: hard iron, where estimated, follows them.
CORE_STATES = 6
#: The prior σ of the magnetometer's hard iron per axis, in the readings'
#: unit (nT in a scenario): a CubeSat's residual hard iron is hundreds of nT.
MAGNETOMETER_BIAS_SIGMA = 1000.0


def estimates_hard_iron(settings) -> bool:
    """Whether ``settings`` (the MEKF's constructor keywords, or a per-run
    object's attributes) turn the magnetometer's hard-iron states on."""
    return bool(settings.get("magnetometer_bias_states", False))


class MagnetometerBiasStates:
    """The hard-iron states' settings and bookkeeping (mixed into
    :class:`~estimators.mekf.MultiplicativeEKF` before
    :class:`~estimators.base.AttitudeAndBiasEstimator`, whose settings these
    extend and whose ``initial_covariance`` they grow; the filter keeps
    ``magnetometer_bias``, the estimate, and applies the states in its
    update, reset and propagation)."""

    def _configure_magnetometer_bias(self, states, sigma) -> None:
        """Validate and keep the hard-iron states' settings; the initial
        covariance grows by their prior where they are on."""
        self.magnetometer_bias_states = boolean("magnetometer_bias_states", states)
        self.initial_magnetometer_bias_sigma = axis_sigmas("initial_magnetometer_bias_sigma",
                                                           sigma)
        if self.magnetometer_bias_states and self.magnetometer_model != "vector":
            raise InvalidParameterError(
                "magnetometer_bias_states", True, "needs magnetometer_model = 'vector' (the "
                f"'{self.magnetometer_model}' model reads the field's direction only)")
        self.state_size = CORE_STATES + 3 * self.magnetometer_bias_states
        if self.magnetometer_bias_states:
            covariance = np.zeros((self.state_size, self.state_size))
            covariance[:CORE_STATES, :CORE_STATES] = self.initial_covariance
            covariance[CORE_STATES:, CORE_STATES:] = np.diag(
                self.initial_magnetometer_bias_sigma ** 2)
            self.initial_covariance = covariance

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """The six-state filters' settings; a declared hard iron
        (``[magnetometer] bias_nT``) turns the magnetometer bias states on,
        their prior at least its size on each axis (as the gyro bias's prior
        covers its declared initial bias)."""
        settings = super().settings_from_scenario(scenario)
        hard_iron = np.abs(np.asarray(getattr(scenario, "magnetometer_bias_nT", np.zeros(3)),
                                      dtype=float))
        if getattr(scenario, "magnetometer_interval_s", None) is not None and np.any(hard_iron):
            settings["magnetometer_bias_states"] = True
            settings["initial_magnetometer_bias_sigma"] = np.maximum(hard_iron,
                                                                     MAGNETOMETER_BIAS_SIGMA)
        return settings

    def _reads_hard_iron(self, observation) -> bool:
        return self.magnetometer_bias_states and observation.sensor == sensing.MAGNETOMETER

    def _less_hard_iron(self, observation):
        """``observation`` as its norm test reads it: a magnetometer's field
        less the hard-iron estimate, where the states are on."""
        tested = observation
        if self._reads_hard_iron(observation):
            tested = replace(observation, body=np.asarray(observation.body, dtype=float)
                             - self.magnetometer_bias)
        return tested
