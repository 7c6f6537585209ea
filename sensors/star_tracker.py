r"""Star trackers: the workshop's noisy quaternion, and a flight-like one whose
error is a small rotation measured in arcseconds.

**The workshop star tracker** (:class:`StarTracker`). At the steps ``k`` that are multiples of ``m = round(T_st / Δt)`` it reads

.. math:: z_k = \frac{q_k + v_k}{\lVert q_k + v_k \rVert}, \qquad
          v_k \sim \mathcal N\!\left(0, \tfrac{p_s}{\Delta t} I_4\right),

with ``p_s`` the star tracker noise power, and raises ``available[k]``.
Between readings the last one is held (the workshop model, "Sensors"). One
``v_k`` is drawn per reading, in time order, and none between readings: the
Simulink noise block runs at ``Δt`` but only its samples at reading steps
ever reach the estimators, and drawing the unused ones would triple the cost
of Monte Carlo campaigns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynamics.quaternion import normalize, quat_from_rotvec, quat_multiply, rotation_matrix
from dynamics.validation import (
    InvalidParameterError,
    finite_number,
    finite_vector,
    nonzero_quaternion,
    one_of,
)
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


#: The longest interval between readings, in steps (a run has at most 1e10).
MAX_STEPS_BETWEEN = 1e12


def steps_between_readings(time_between_measurements: float, dt: float) -> int:
    """``m = T_st / Δt`` as an int; rejects a ``T_st`` that is not a positive
    whole multiple of ``Δt``."""
    ratio = time_between_measurements / dt
    if not ratio < MAX_STEPS_BETWEEN:        # round(inf) would overflow
        raise InvalidParameterError(
            "time_between_measurements", time_between_measurements,
            f"must be at most {MAX_STEPS_BETWEEN:.0e} steps of dt = {dt:g}")
    steps = round(ratio)
    if steps < 1 or abs(ratio - steps) > _WHOLE_MULTIPLE_TOLERANCE * max(1.0, ratio):
        raise InvalidParameterError(
            "time_between_measurements", time_between_measurements,
            f"must be a positive whole multiple of dt = {dt:g}")
    return steps


class StarTracker:
    """A star tracker reading every ``time_between_measurements`` seconds.

    Both trackers (this, the workshop's, and :class:`RotationStarTracker`)
    answer one interface: ``model``, ``measure(q_true, rng, dropout_rng)``,
    ``attitude_covariance_rad2``, ``dropout_probability`` and
    ``in_outage(time_s)``; this one never drops a reading.

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

    model = "workshop"
    #: It reads at every scheduled step: no dropouts, no outages.
    dropout_probability = 0.0

    def __init__(self, noise_power: float, time_between_measurements: float, dt: float):
        self.noise_power = finite_number("star_tracker_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.time_between_measurements = finite_number(
            "time_between_measurements", time_between_measurements, strictly_positive=True)
        self.steps_between_readings = steps_between_readings(self.time_between_measurements,
                                                             self.dt)
        self.std = noise_power_to_std(self.noise_power, self.dt)

    @property
    def attitude_covariance_rad2(self) -> np.ndarray:
        """Covariance (rad²) of a reading's body-frame small-angle error, to first
        order: the normalised ``q + v`` is off by ``2 v⊥``, so ``(2σ)² I₃``."""
        return (2.0 * self.std) ** 2 * np.eye(3)

    def in_outage(self, time_s: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: all False (no outage windows)."""
        return np.zeros(np.shape(time_s), dtype=bool)

    def measure(self, q_true: np.ndarray, rng: np.random.Generator,
                dropout_rng: np.random.Generator | None = None) -> StarTrackerReadings:
        """Held readings for true attitudes ``(N, 4)``.

        Draws one row of 4 standard normals from ``rng`` per reading, in time
        order (``dropout_rng`` is not drawn from: no reading is lost).
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


#: Arcseconds per radian.
ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0
SIGN_CONVENTIONS = ("raw", "canonical")


def outage_windows(name: str, value) -> tuple[tuple[float, float], ...]:
    """``[[start, stop], ...]`` in seconds, each ``0 <= start < stop``."""
    try:
        windows = [tuple(float(x) for x in pair) for pair in value]
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, "must be a list of [start, stop] pairs in "
                                    "seconds") from None
    if any(len(pair) != 2 for pair in windows):
        raise InvalidParameterError(name, value, "must be a list of [start, stop] pairs in "
                                    "seconds")
    for start, stop in windows:
        if not (np.isfinite(start) and np.isfinite(stop) and 0 <= start < stop):
            raise InvalidParameterError(name, value, "each [start, stop] must be finite with "
                                        "0 <= start < stop")
    return tuple(windows)


class RotationStarTracker:
    """A star tracker whose error is a small rotation in its own frame.

    Parameters
    ----------
    sigma_arcsec : (3,) array-like
        Standard deviation of the error rotation about the sensor's x, y
        (cross-boresight) and z (boresight, roll) axes, arcseconds.
    time_between_measurements : float
        Seconds between scheduled readings; a positive whole multiple of ``dt``.
    dt : float
        Simulation step, seconds.
    dropout_probability : float
        Chance in [0, 1) that a scheduled reading is lost.
    outages_s : list of [start, stop]
        Windows (seconds, start included, stop excluded) with no readings.
    sign : {"raw", "canonical"}
        Report ``q ⊗ δq`` as it comes, or its ``w >= 0`` representative.
    sensor_to_body_quat : (4,) array-like
        Rotation from the sensor frame to the body frame (scalar-first).
    """

    model = "rotation"

    def __init__(self, sigma_arcsec, time_between_measurements: float, dt: float, *,
                 dropout_probability: float = 0.0, outages_s=(), sign: str = "raw",
                 sensor_to_body_quat=(1.0, 0.0, 0.0, 0.0)):
        self.sigma_arcsec = finite_vector("star_tracker_sigma_arcsec", sigma_arcsec, 3)
        if np.any(self.sigma_arcsec < 0):
            raise InvalidParameterError("star_tracker_sigma_arcsec", sigma_arcsec,
                                        "must be >= 0 on every axis")
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.time_between_measurements = finite_number(
            "time_between_measurements", time_between_measurements, strictly_positive=True)
        self.steps_between_readings = steps_between_readings(self.time_between_measurements,
                                                             self.dt)
        self.dropout_probability = finite_number("star_tracker_dropout_probability",
                                                 dropout_probability, minimum=0.0)
        if self.dropout_probability >= 1.0:
            raise InvalidParameterError("star_tracker_dropout_probability", dropout_probability,
                                        "must be < 1")
        self.outages_s = outage_windows("star_tracker_outages_s", outages_s)
        self.sign = one_of("star_tracker_sign", sign, SIGN_CONVENTIONS)
        self.sensor_to_body_quat = nonzero_quaternion("star_tracker_to_body_quat",
                                                      sensor_to_body_quat)
        self.sigma_rad = self.sigma_arcsec / ARCSEC_PER_RAD
        self.sensor_to_body = rotation_matrix(self.sensor_to_body_quat)

    @property
    def attitude_covariance_rad2(self) -> np.ndarray:
        """Covariance (rad²) of a reading's body-frame error: ``R_bs diag(σ²) R_bsᵀ``."""
        return self.sensor_to_body @ np.diag(self.sigma_rad ** 2) @ self.sensor_to_body.T

    def scheduled(self, n_steps: int) -> np.ndarray:
        """``(N,)`` bool: the steps a reading is due (``k`` a multiple of ``m``)."""
        due = np.zeros(n_steps, dtype=bool)
        due[::self.steps_between_readings] = True
        return due

    def in_outage(self, time_s: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: the times inside a scheduled outage window."""
        time_s = np.asarray(time_s, dtype=float)
        lost = np.zeros(time_s.shape, dtype=bool)
        for start, stop in self.outages_s:
            lost |= (time_s >= start) & (time_s < stop)
        return lost

    def error_rotations(self, normals: np.ndarray, q_true: np.ndarray) -> np.ndarray:
        """Readings ``q ⊗ δq(R_bs σ N)`` for rows of normals ``(n, 3)`` and truth ``(n, 4)``,
        with the sign convention applied."""
        theta_body = (normals * self.sigma_rad) @ self.sensor_to_body.T
        readings = normalize(quat_multiply(q_true, quat_from_rotvec(theta_body)))
        if self.sign == "canonical":
            readings = np.where(readings[:, :1] < 0, -readings, readings)
        return readings

    def measure(self, q_true: np.ndarray, rng: np.random.Generator,
                dropout_rng: np.random.Generator | None = None) -> StarTrackerReadings:
        """Held readings for true attitudes ``(N, 4)`` on the grid ``t_k = k dt``.

        Draws 3 standard normals from ``rng`` per scheduled reading, in time
        order, and (with a dropout probability) one uniform per scheduled
        reading from ``dropout_rng``.
        """
        q_true = np.asarray(q_true, dtype=float)
        n_steps = len(q_true)
        due = self.scheduled(n_steps)
        normals = rng.standard_normal((int(due.sum()), 3))
        available = due & ~self.in_outage(np.arange(n_steps) * self.dt)
        if self.dropout_probability > 0:
            if dropout_rng is None:
                raise ValueError("dropout_rng is needed when dropout_probability > 0")
            kept = dropout_rng.random(int(due.sum())) >= self.dropout_probability
            available[due] &= kept
        readings = np.vstack([[1.0, 0.0, 0.0, 0.0],
                              self.error_rotations(normals, q_true[due])[available[due]]])
        # Sample and hold; row 0 is the [1, 0, 0, 0] held before any reading.
        return StarTrackerReadings(quat=readings[np.cumsum(available)], available=available)
