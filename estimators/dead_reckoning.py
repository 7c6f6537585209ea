r"""Dead reckoning: integrate the gyro, ignore the star tracker.

.. math:: \hat q_k = f(\hat q_{k-1}, \tilde\omega_k), \qquad \hat q_{-1} = q_0,

with ``f`` the normalised first-order step of :mod:`estimators.model`
(workshop model, SPEC "The three estimators", item 1). Gyro white noise of
power ``p`` makes the error grow as an angle random walk: after ``t``
seconds each axis has drifted by about ``√(p t)`` radians (Markley &
Crassidis 2014, §6.2.2).
"""
from __future__ import annotations

import numpy as np

from estimators.base import AttitudeEstimator
from estimators.model import propagate

IDENTITY = (1.0, 0.0, 0.0, 0.0)


class DeadReckoning(AttitudeEstimator):
    """Gyro-only attitude propagation.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,) array-like
        Starting estimate ``q̂[-1]``, scalar-first; normalised.
    """

    name = "dead-reckoning"
    label = "Dead Reckoning"

    def __init__(self, *, dt: float = 0.01, initial_attitude=IDENTITY):
        super().__init__(dt=dt, initial_attitude=initial_attitude)
        self.reset()

    def reset(self) -> None:
        self.attitude = self.initial_attitude.copy()

    def step(self, omega_meas_radps, star_tracker_quat=None) -> np.ndarray:
        self.attitude = propagate(self.attitude, np.asarray(omega_meas_radps, float), self.dt)
        return self.attitude.copy()
