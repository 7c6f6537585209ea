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
    #: (N,) seconds after each step's time that its reading was taken (0 on
    #: the gyro grid, and where there is none).
    offset_s: np.ndarray | None = None


#: The longest interval between readings, in steps (a run has at most 1e10).
MAX_STEPS_BETWEEN = 1e12


def reading_interval(time_between_measurements: float, dt: float) -> float:
    """A tracker interval on its own clock: at least ``dt`` (a tracker faster
    than the gyro would deliver two readings in one step) and at most
    :data:`MAX_STEPS_BETWEEN` steps; need not be a multiple of ``dt``."""
    name = "star_tracker.interval_s (time_between_measurements)"
    interval = finite_number(name, time_between_measurements, strictly_positive=True)
    ratio = interval / dt
    if not ratio < MAX_STEPS_BETWEEN:
        raise InvalidParameterError(name, interval,
                                    f"must be at most {MAX_STEPS_BETWEEN:.0e} steps of dt = {dt:g}")
    if ratio < 1.0 - _WHOLE_MULTIPLE_TOLERANCE:
        raise InvalidParameterError(name, interval, f"must be >= the gyro's dt = {dt:g}: each "
                                    "gyro step takes at most one reading")
    return interval


def on_gyro_grid(time_between_measurements: float, dt: float) -> bool:
    """Whether readings fall on gyro steps: ``T_st`` a whole multiple of ``Δt``."""
    ratio = time_between_measurements / dt
    return abs(ratio - round(ratio)) <= _WHOLE_MULTIPLE_TOLERANCE * max(1.0, ratio)


def reading_schedule(time_between_measurements: float, dt: float, n_steps: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    r"""When a tracker on its own clock reads: ``(steps, offsets)``.

    Reading ``j`` is taken at :math:`t_j = j T_{st}` (up to the last gyro
    step's time) and delivered at the gyro step :math:`k_j = \lfloor t_j /
    \Delta t \rfloor` whose interval :math:`[t_k, t_{k+1})` holds it,
    :math:`\tau_j = t_j - k_j \Delta t` after that step's time (0 on the
    grid). An estimator outputs its estimate at :math:`t_k`, propagates to
    :math:`t_k + \tau`, updates, and propagates on to :math:`t_{k+1}`
    (:meth:`estimators.AttitudeEstimator.step`).
    """
    if on_gyro_grid(time_between_measurements, dt):
        steps = np.arange(0, n_steps, steps_between_readings(time_between_measurements, dt))
        return steps, np.zeros(len(steps))
    last_time = (n_steps - 1) * dt
    times = np.arange(int(last_time / time_between_measurements + 1e-9) + 1) * \
        time_between_measurements
    steps = np.minimum(np.floor(times / dt + 1e-9).astype(np.int64), n_steps - 1)
    offsets = np.maximum(times - steps * dt, 0.0)
    offsets[offsets < 1e-9 * dt] = 0.0
    return steps, offsets


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
        Seconds between readings, at least ``dt``; off the gyro's grid the
        readings carry their own times (:func:`reading_schedule`).
    dt : float
        Simulation step in seconds.
    """

    model = "workshop"
    #: It reads at every scheduled step: no dropouts, no outages.
    dropout_probability = 0.0

    def __init__(self, noise_power: float, time_between_measurements: float, dt: float):
        self.noise_power = finite_number("star_tracker_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.time_between_measurements = reading_interval(time_between_measurements, self.dt)
        #: ``m`` with readings every ``m`` steps, or None off the gyro grid.
        self.steps_between_readings = (
            steps_between_readings(self.time_between_measurements, self.dt)
            if on_gyro_grid(self.time_between_measurements, self.dt) else None)
        self.std = noise_power_to_std(self.noise_power, self.dt)

    @property
    def attitude_covariance_rad2(self) -> np.ndarray:
        """Covariance (rad²) of a reading's body-frame small-angle error, to first
        order: the normalised ``q + v`` is off by ``2 v⊥``, so ``(2σ)² I₃``."""
        return (2.0 * self.std) ** 2 * np.eye(3)

    def in_outage(self, time_s: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: all False (no outage windows)."""
        return np.zeros(np.shape(time_s), dtype=bool)

    def schedule(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """The steps that take a reading and each reading's offset after its
        step's time (:func:`reading_schedule`)."""
        return reading_schedule(self.time_between_measurements, self.dt, n_steps)

    def measure(self, q_true: np.ndarray, rng: np.random.Generator,
                dropout_rng: np.random.Generator | None = None,
                reading_quat: np.ndarray | None = None) -> StarTrackerReadings:
        """Held readings for true attitudes ``(N, 4)`` on the gyro's grid;
        off the grid, ``reading_quat`` holds the true attitude at each
        scheduled reading's own time (:meth:`schedule`).

        Draws one row of 4 standard normals from ``rng`` per reading, in time
        order (``dropout_rng`` is not drawn from: no reading is lost).
        """
        q_true = np.asarray(q_true, dtype=float)
        n_steps = len(q_true)
        steps, offsets = self.schedule(n_steps)
        truth = _truth_at_readings(q_true, steps, offsets, reading_quat)
        available = np.zeros(n_steps, dtype=bool)
        available[steps] = True
        noise = self.std * rng.standard_normal((len(steps), 4))
        readings = normalize(truth + noise)
        # Sample and hold: every step carries the latest reading taken. The
        # first reading is at k = 0, so the [1, 0, 0, 0] that the Simulink
        # hold starts from is never seen on this grid.
        quat = readings[np.cumsum(available) - 1]
        return StarTrackerReadings(quat=quat, available=available,
                                   offset_s=_offsets_on_grid(n_steps, steps, offsets))


def _truth_at_readings(q_true, steps, offsets, reading_quat) -> np.ndarray:
    """The true attitude at each scheduled reading: on the grid, the step's;
    off it, ``reading_quat`` (which the caller integrates at those times)."""
    if reading_quat is None:
        if np.any(offsets):
            raise ValueError("readings off the gyro grid need reading_quat, the true "
                             "attitude at each reading's time")
        return q_true[steps]
    reading_quat = np.asarray(reading_quat, dtype=float)
    if reading_quat.shape != (len(steps), 4):
        raise ValueError(f"reading_quat must have shape ({len(steps)}, 4): one row per "
                         "scheduled reading")
    return reading_quat


def _offsets_on_grid(n_steps: int, steps, offsets) -> np.ndarray:
    """``(N,)`` each step's reading offset, 0 where it takes none."""
    grid = np.zeros(n_steps)
    grid[steps] = offsets
    return grid


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


#: The largest error σ of the rotation model, arcsec: 180°.
MAX_SIGMA_ARCSEC = 648000.0


class RotationStarTracker:
    """A star tracker whose error is a small rotation in its own frame.

    Parameters
    ----------
    sigma_arcsec : (3,) array-like
        Standard deviation of the error rotation about the sensor's x, y
        (cross-boresight) and z (boresight, roll) axes, arcseconds.
    time_between_measurements : float
        Seconds between scheduled readings, at least ``dt``; off the gyro's
        grid the readings carry their own times (:func:`reading_schedule`).
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
        if np.any(self.sigma_arcsec > MAX_SIGMA_ARCSEC):
            raise InvalidParameterError("star_tracker_sigma_arcsec", sigma_arcsec,
                                        f"must be at most {MAX_SIGMA_ARCSEC:g} arcsec (180°) on "
                                        "every axis: no rotation is further from another")
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.time_between_measurements = reading_interval(time_between_measurements, self.dt)
        #: ``m`` with readings every ``m`` steps, or None off the gyro grid.
        self.steps_between_readings = (
            steps_between_readings(self.time_between_measurements, self.dt)
            if on_gyro_grid(self.time_between_measurements, self.dt) else None)
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

    def schedule(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """The steps that take a scheduled reading and each one's offset after
        its step's time (:func:`reading_schedule`)."""
        return reading_schedule(self.time_between_measurements, self.dt, n_steps)

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
                dropout_rng: np.random.Generator | None = None,
                reading_quat: np.ndarray | None = None) -> StarTrackerReadings:
        """Held readings for true attitudes ``(N, 4)`` on the grid ``t_k = k dt``;
        off the grid, ``reading_quat`` holds the true attitude at each
        scheduled reading's own time (:meth:`schedule`).

        Draws 3 standard normals from ``rng`` per scheduled reading, in time
        order, and (with a dropout probability) one uniform per scheduled
        reading from ``dropout_rng``. Outages are judged at each reading's time.
        """
        q_true = np.asarray(q_true, dtype=float)
        n_steps = len(q_true)
        steps, offsets = self.schedule(n_steps)
        truth = _truth_at_readings(q_true, steps, offsets, reading_quat)
        normals = rng.standard_normal((len(steps), 3))
        kept = ~self.in_outage(steps * self.dt + offsets)
        if self.dropout_probability > 0:
            if dropout_rng is None:
                raise ValueError("dropout_rng is needed when dropout_probability > 0")
            kept &= dropout_rng.random(len(steps)) >= self.dropout_probability
        available = np.zeros(n_steps, dtype=bool)
        available[steps[kept]] = True
        readings = np.vstack([[1.0, 0.0, 0.0, 0.0],
                              self.error_rotations(normals, truth)[kept]])
        # Sample and hold; row 0 is the [1, 0, 0, 0] held before any reading.
        return StarTrackerReadings(quat=readings[np.cumsum(available)], available=available,
                                   offset_s=_offsets_on_grid(n_steps, steps[kept],
                                                             offsets[kept]))


class NoStarTracker:
    """No star tracker (``[star_tracker] model = "none"``): a spacecraft that
    determines its attitude from vector sensors alone. It answers the
    trackers' interface with no reading ever (held readings are the identity,
    never flagged available)."""

    model = "none"
    dropout_probability = 0.0

    def __init__(self, time_between_measurements: float, dt: float):
        self.time_between_measurements = time_between_measurements
        self.dt = dt

    @property
    def attitude_covariance_rad2(self) -> np.ndarray:
        """1 rad² per axis: a placeholder that no update ever uses (there is no reading)."""
        return np.eye(3)

    def in_outage(self, time_s: np.ndarray) -> np.ndarray:
        return np.ones(np.shape(time_s), dtype=bool)

    def schedule(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, dtype=np.int64), np.zeros(0)

    def measure(self, q_true: np.ndarray, rng: np.random.Generator,
                dropout_rng: np.random.Generator | None = None,
                reading_quat: np.ndarray | None = None) -> StarTrackerReadings:
        """No readings: nothing is drawn from either generator."""
        n_steps = len(q_true)
        quat = np.zeros((n_steps, 4))
        quat[:, 0] = 1.0
        return StarTrackerReadings(quat=quat, available=np.zeros(n_steps, dtype=bool),
                                   offset_s=np.zeros(n_steps))
