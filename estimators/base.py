"""The one interface every attitude estimator shares.

An estimator is fed, once per gyro step ``k``, the measured body rate and,
when the star tracker took a reading at that step, the reading; it answers
with its attitude estimate ``q̂[k]`` (scalar-first, unit norm). Swapping one
estimator for another is one line::

    estimator = DeadReckoning(dt=0.01)          # or QuaternionEKF(dt=0.01)
    q_est = estimator.run(omega_meas_radps, star_quat, available)

All arrays in and out are 1-D per step (``(3,)`` rates, ``(4,)``
quaternions) or stacked ``(N, ...)`` for whole runs.
"""
from __future__ import annotations

import numpy as np

from dynamics.validation import finite_number, nonzero_quaternion


class AttitudeEstimator:
    """Base class: subclasses implement :meth:`step` and :meth:`reset`.

    Attributes
    ----------
    name : str
        Short identifier used on the command line (``"ekf"``).
    label : str
        Human-readable name used in figure legends.
    dt : float
        Step in seconds between gyro samples.
    """

    name = "estimator"
    label = "Estimator"

    def __init__(self, *, dt: float, initial_attitude):
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.initial_attitude = nonzero_quaternion("initial_state", initial_attitude)

    def reset(self) -> None:
        """Return to the initial estimate, forgetting all measurements."""
        raise NotImplementedError

    def step(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray | None = None
             ) -> np.ndarray:
        """Consume step ``k``'s measurements and return ``q̂[k]`` as a ``(4,)`` array.

        Parameters
        ----------
        omega_meas_radps : (3,) array
            Gyro reading at step ``k``, rad/s, body frame.
        star_tracker_quat : (4,) array or None
            The star tracker's reading if one was taken at step ``k``
            (``available[k]``), else None.
        """
        raise NotImplementedError

    def run(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
            available: np.ndarray) -> np.ndarray:
        """Reset, then step through a whole record; returns ``(N, 4)`` estimates.

        Parameters
        ----------
        omega_meas_radps : (N, 3) array, rad/s
        star_tracker_quat : (N, 4) array, the held star tracker output
        available : (N,) bool array, True where a new reading was taken
        """
        self.reset()
        omega = np.asarray(omega_meas_radps, dtype=float)
        star = np.asarray(star_tracker_quat, dtype=float)
        available = np.asarray(available, dtype=bool)
        estimates = np.empty((len(omega), 4))
        for k in range(len(omega)):
            estimates[k] = self.step(omega[k], star[k] if available[k] else None)
        return estimates

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dt={self.dt!r})"
