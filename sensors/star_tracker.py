r"""Star tracker: a noisy, renormalised attitude quaternion at a slower rate.

At the steps ``k`` that are multiples of ``m = round(T_st / Δt)`` it reads

.. math:: z_k = \frac{q_k + v_k}{\lVert q_k + v_k \rVert}, \qquad
          v_k \sim \mathcal N\!\left(0, \tfrac{p_s}{\Delta t} I_4\right),

with ``p_s`` the star tracker noise power, and raises ``available[k]``.
Between readings the last one is held (workshop model, SPEC "Sensors"). One
``v_k`` is drawn per reading, in time order, and none between readings: the
Simulink noise block runs at ``Δt`` but only its samples at reading steps
ever reach the estimators, and drawing the unused ones would triple the cost
of Monte Carlo campaigns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynamics.quaternion import normalize
from dynamics.validation import InvalidParameterError, finite_number
from sensors.noise import noise_power_to_std

# How far T_st / Δt may sit from a whole number and still count as one
# (absorbs the binary rounding of values such as 0.2 / 0.01).
_WHOLE_MULTIPLE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class StarTrackerReadings:
    """Held star tracker output on the time grid.

    Attributes
    ----------
    quat : (N, 4) array, the held reading (scalar-first, unit norm)
    available : (N,) bool array, True at the steps a new reading is taken
    """

    quat: np.ndarray
    available: np.ndarray


def steps_between_readings(time_between_measurements: float, dt: float) -> int:
    """``m = T_st / Δt`` as an int; rejects a ``T_st`` that is not a positive
    whole multiple of ``Δt``."""
    ratio = time_between_measurements / dt
    steps = round(ratio)
    if steps < 1 or abs(ratio - steps) > _WHOLE_MULTIPLE_TOLERANCE * max(1.0, ratio):
        raise InvalidParameterError(
            "time_between_measurements", time_between_measurements,
            f"must be a positive whole multiple of dt = {dt:g}")
    return steps


class StarTracker:
    """A star tracker reading every ``time_between_measurements`` seconds.

    Parameters
    ----------
    noise_power : float
        Noise power ``p_s`` per quaternion component (Simulink band-limited
        white noise sampled at ``dt``).
    time_between_measurements : float
        Seconds between readings; a positive whole multiple of ``dt``.
    dt : float
        Simulation step in seconds.
    """

    def __init__(self, noise_power: float, time_between_measurements: float, dt: float):
        self.noise_power = finite_number("star_tracker_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.time_between_measurements = finite_number(
            "time_between_measurements", time_between_measurements, strictly_positive=True)
        self.steps_between_readings = steps_between_readings(self.time_between_measurements,
                                                             self.dt)
        self.std = noise_power_to_std(self.noise_power, self.dt)

    def measure(self, q_true: np.ndarray, rng: np.random.Generator) -> StarTrackerReadings:
        """Held readings for true attitudes ``(N, 4)``.

        Draws one row of 4 standard normals from ``rng`` per reading, in time
        order.
        """
        q_true = np.asarray(q_true, dtype=float)
        n_steps = len(q_true)
        available = np.zeros(n_steps, dtype=bool)
        available[::self.steps_between_readings] = True
        noise = self.std * rng.standard_normal((int(available.sum()), 4))
        readings = normalize(q_true[available] + noise)
        # Sample and hold: every step carries the latest reading taken. The
        # first reading is at k = 0, so the [1, 0, 0, 0] that the Simulink
        # hold starts from is never seen on this grid.
        quat = readings[np.cumsum(available) - 1]
        return StarTrackerReadings(quat=quat, available=available)
