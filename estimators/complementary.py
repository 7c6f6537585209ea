r"""The complementary filters most IMU users run: Madgwick's gradient-descent
filter and Mahony's explicit complementary filter, with the accelerometer
(gravity) and the magnetometer, on an earth frame whose x axis is magnetic
north, y west and z up (NWU), as their authors write them; the estimate
turned to ENU, the reference frame of this toolkit's recordings and ground
sites, and about the vertical by the declination of the field's reference
vector (:class:`MagneticFrame`: on a recording the field's reference points
north, so nothing turns; on a simulated site it is the IGRF's declination,
a few degrees that would otherwise be scored as their error).

* Madgwick, "An efficient orientation filter for inertial and
  inertial/magnetic sensor arrays" (2010), §3–4 (his C code,
  ``MadgwickAHRSupdate``): the gyro's quaternion rate minus β times the
  normalised gradient of the acc/mag alignment error. ``madgwick`` is the
  paper's filter. ``madgwick-broad`` is the C code as the BROAD authors ran
  it, which stores the field's reference components :math:`b_x, b_z` where
  the paper's equations take :math:`2b_x, 2b_z` (the dataset's issue #1):
  its predicted field is half the measured one. Their published numbers are
  that variant's; the two are named apart so neither passes for the other.
* Mahony, Hamel & Pflimlin, "Nonlinear complementary filters on the special
  orthogonal group" (IEEE TAC 2008), the explicit complementary filter as in
  Madgwick's C code (``MahonyAHRSupdate``): the rate corrected by
  :math:`K_p e + K_i \int e\,dt`, with :math:`e` the cross products of the
  measured and predicted gravity and field directions.

Timing, as their C code: step ``k`` integrates rate ``k`` over the sample
interval that ends at ``k``, corrects with the acc/mag readings of ``k``,
and outputs the result. Step 0 integrates rate 0 too, from the start
attitude (``rate_timing = "workshop"``, as dead reckoning's); where the
start is the attitude *at* sample 0 (a recording's, TRIAD on its first
sample), ``rate_timing = "end"`` leaves rate 0, the time before it, out:
step 0 only corrects (a start in motion at 300 °/s is otherwise 1–2° off
from its first sample). As there, a step without a field reading corrects
with gravity alone (``MadgwickAHRSupdateIMU``, ``MahonyAHRSupdateIMU``: a
6-axis IMU, or the samples between a slower magnetometer's readings), and
a step without an accelerometer reading integrates the rate alone. The acc and mag readings come as vector readings
(:class:`sensors.vector.VectorObservation`, sensors ``"accelerometer"`` and
``"magnetometer"``); their reference vectors are not used — these filters
define their own earth frame by the field's measured inclination.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import IDENTITY, quat_conjugate, quat_multiply
from dynamics.validation import finite_number, one_of
from estimators import sensing
from estimators.base import AttitudeEstimator
from estimators.settings import DEFAULT_DT_S
from estimators.tunable import Tunable

#: ENU from NWU: a quarter turn about the vertical, q_ENU = NWU_TO_ENU ⊗ q_NWU.
NWU_TO_ENU = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])
ENU_TO_NWU = NWU_TO_ENU * np.array([1.0, -1.0, -1.0, -1.0])


#: A reading that is absent: the steps below then only integrate the rate.
NO_READING = (0.0, 0.0, 0.0)
#: Whether step 0 integrates rate 0 (module docstring).
RATE_TIMINGS = ("workshop", "end")


def madgwick_step(q, gyro, acc, mag, beta: float, dt: float, halved_field: bool):
    """One step of Madgwick's C code, its MARG or IMU update (module
    docstring; the IMU's gradient is the MARG's gravity terms, which the C
    code expands), tuples of floats in and out; ``halved_field``: the BROAD
    authors' variant. Plain scalar arithmetic, element by element as the C
    code, so that the engine compiles this very function."""
    q0, q1, q2, q3 = q
    (gx, gy, gz), (ax, ay, az), (mx, my, mz) = gyro, acc, mag
    d0 = 0.5 * (-q1 * gx - q2 * gy - q3 * gz)
    d1 = 0.5 * (q0 * gx + q2 * gz - q3 * gy)
    d2 = 0.5 * (q0 * gy - q1 * gz + q3 * gx)
    d3 = 0.5 * (q0 * gz + q1 * gy - q2 * gx)
    s0 = s1 = s2 = s3 = 0.0
    gravity = ax != 0.0 or ay != 0.0 or az != 0.0
    if gravity:
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        _2q0, _2q1, _2q2, _2q3 = 2 * q0, 2 * q1, 2 * q2, 2 * q3
        q0q0, q0q1, q0q2, q0q3 = q0 * q0, q0 * q1, q0 * q2, q0 * q3
        q1q1, q1q2, q1q3 = q1 * q1, q1 * q2, q1 * q3
        q2q2, q2q3, q3q3 = q2 * q2, q2 * q3, q3 * q3
        g1 = 2 * q1q3 - 2 * q0 * q2 - ax
        g2 = 2 * q0q1 + 2 * q2 * q3 - ay
        g3 = 1 - 2 * q1q1 - 2 * q2q2 - az
        s0 = -_2q2 * g1 + _2q1 * g2
        s1 = _2q3 * g1 + _2q0 * g2 - 4 * q1 * g3
        s2 = -_2q0 * g1 + _2q3 * g2 - 4 * q2 * g3
        s3 = _2q1 * g1 + _2q2 * g2
    if gravity and (mx != 0.0 or my != 0.0 or mz != 0.0):
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        mx, my, mz = mx / norm, my / norm, mz / norm
        _2q0mx, _2q0my, _2q0mz, _2q1mx = 2 * q0 * mx, 2 * q0 * my, 2 * q0 * mz, 2 * q1 * mx
        hx = (mx * q0q0 - _2q0my * q3 + _2q0mz * q2 + mx * q1q1 + _2q1 * my * q2
              + _2q1 * mz * q3 - mx * q2q2 - mx * q3q3)
        hy = (_2q0mx * q3 + my * q0q0 - _2q0mz * q1 + _2q1mx * q2 - my * q1q1 + my * q2q2
              + _2q2 * mz * q3 - my * q3q3)
        bx = math.sqrt(hx * hx + hy * hy)
        bz = (-_2q0mx * q2 + _2q0my * q1 + mz * q0q0 + _2q1mx * q3 - mz * q1q1
              + _2q2 * my * q3 - mz * q2q2 + mz * q3q3)
        factor = 1.0 if halved_field else 2.0
        _2bx, _2bz = factor * bx, factor * bz
        _4bx, _4bz = 2 * _2bx, 2 * _2bz
        fx = _2bx * (0.5 - q2q2 - q3q3) + _2bz * (q1q3 - q0q2) - mx
        fy = _2bx * (q1q2 - q0q3) + _2bz * (q0q1 + q2q3) - my
        fz = _2bx * (q0q2 + q1q3) + _2bz * (0.5 - q1q1 - q2q2) - mz
        s0 = s0 - _2bz * q2 * fx + (-_2bx * q3 + _2bz * q1) * fy + _2bx * q2 * fz
        s1 = s1 + _2bz * q3 * fx + (_2bx * q2 + _2bz * q0) * fy + (_2bx * q3 - _4bz * q1) * fz
        s2 = s2 + (-_4bx * q2 - _2bz * q0) * fx + (_2bx * q1 + _2bz * q3) * fy \
            + (_2bx * q0 - _4bz * q2) * fz
        s3 = s3 + (-_4bx * q3 + _2bz * q1) * fx + (-_2bx * q0 + _2bz * q2) * fy + _2bx * q1 * fz
    norm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
    if norm > 0.0:
        d0 -= beta * s0 / norm
        d1 -= beta * s1 / norm
        d2 -= beta * s2 / norm
        d3 -= beta * s3 / norm
    q0, q1, q2, q3 = q0 + d0 * dt, q1 + d1 * dt, q2 + d2 * dt, q3 + d3 * dt
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 / norm, q1 / norm, q2 / norm, q3 / norm


def mahony_step(q, integral, gyro, acc, mag, kp: float, ki: float, dt: float):
    """One step of Mahony's filter as Madgwick's C code writes it
    (``MahonyAHRSupdate``, or ``MahonyAHRSupdateIMU`` without a field
    reading, as :func:`madgwick_step`); returns ``(q, integral)`` (the integral of :math:`K_i e`, rad/s). Plain
    scalar arithmetic, as :func:`madgwick_step`."""
    q0, q1, q2, q3 = q
    gx, gy, gz = gyro
    ix, iy, iz = integral
    ax, ay, az = acc
    mx, my, mz = mag
    if (ax != 0.0 or ay != 0.0 or az != 0.0) and (mx != 0.0 or my != 0.0 or mz != 0.0):
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        mx, my, mz = mx / norm, my / norm, mz / norm
        q0q0, q0q1, q0q2, q0q3 = q0 * q0, q0 * q1, q0 * q2, q0 * q3
        q1q1, q1q2, q1q3 = q1 * q1, q1 * q2, q1 * q3
        q2q2, q2q3, q3q3 = q2 * q2, q2 * q3, q3 * q3
        hx = 2 * (mx * (0.5 - q2q2 - q3q3) + my * (q1q2 - q0q3) + mz * (q1q3 + q0q2))
        hy = 2 * (mx * (q1q2 + q0q3) + my * (0.5 - q1q1 - q3q3) + mz * (q2q3 - q0q1))
        bx = math.sqrt(hx * hx + hy * hy)
        bz = 2 * (mx * (q1q3 - q0q2) + my * (q2q3 + q0q1) + mz * (0.5 - q1q1 - q2q2))
        vx, vy, vz = q1q3 - q0q2, q0q1 + q2q3, q0q0 - 0.5 + q3q3
        wx = bx * (0.5 - q2q2 - q3q3) + bz * (q1q3 - q0q2)
        wy = bx * (q1q2 - q0q3) + bz * (q0q1 + q2q3)
        wz = bx * (q0q2 + q1q3) + bz * (0.5 - q1q1 - q2q2)
        ex = (ay * vz - az * vy) + (my * wz - mz * wy)
        ey = (az * vx - ax * vz) + (mz * wx - mx * wz)
        ez = (ax * vy - ay * vx) + (mx * wy - my * wx)
        feedback = True
    elif ax != 0.0 or ay != 0.0 or az != 0.0:
        # MahonyAHRSupdateIMU: the gravity's cross product alone
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        vx, vy, vz = q1 * q3 - q0 * q2, q0 * q1 + q2 * q3, q0 * q0 - 0.5 + q3 * q3
        ex, ey, ez = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
        feedback = True
    else:
        ex = ey = ez = 0.0
        feedback = False
    if feedback:
        if ki > 0.0:
            ix, iy, iz = ix + 2 * ki * ex * dt, iy + 2 * ki * ey * dt, iz + 2 * ki * ez * dt
            gx, gy, gz = gx + ix, gy + iy, gz + iz
        else:
            ix = iy = iz = 0.0
        gx, gy, gz = gx + 2 * kp * ex, gy + 2 * kp * ey, gz + 2 * kp * ez
    gx, gy, gz = 0.5 * dt * gx, 0.5 * dt * gy, 0.5 * dt * gz
    q0, q1, q2, q3 = (q0 - q1 * gx - q2 * gy - q3 * gz, q1 + q0 * gx + q2 * gz - q3 * gy,
                      q2 + q0 * gy - q1 * gz + q3 * gx, q3 + q0 * gz + q1 * gy - q2 * gx)
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return (q0 / norm, q1 / norm, q2 / norm, q3 / norm), (ix, iy, iz)


def acc_mag(vectors):
    """The accelerometer's and the magnetometer's readings among a step's
    vector readings (None where absent)."""
    found = {v.sensor: tuple(float(x) for x in v.body) for v in vectors}
    return found.get("accelerometer"), found.get("magnetometer")


def declination_turn(field_reference) -> np.ndarray | None:
    r"""The turn about the vertical from the frame these filters (and VQF,
    Fusion) estimate in — their north is the field's horizontal direction,
    *magnetic* north — to the reference frame (east-north-up): ``q_ref =
    turn ⊗ q_magnetic``, a rotation by :math:`-D` about up, :math:`D =
    \operatorname{atan2}(r_E, r_N)` the declination of the field's reference
    vector ``field_reference`` (ENU). None where it has no east component
    (no declination: a recording's field reference points north by
    construction), so that nothing changes there, bit for bit."""
    east, north = float(field_reference[0]), float(field_reference[1])
    if east == 0.0:
        return None
    half = -0.5 * math.atan2(east, north)
    return np.array([math.cos(half), 0.0, 0.0, math.sin(half)])


def field_reference(vectors):
    """The magnetometer's reference vector among a step's readings, or None."""
    return next((v.reference for v in vectors if v.sensor == "magnetometer"), None)


class MagneticFrame:
    """What estimators in the magnetic frame share: the turn to the reference
    frame, learnt from the first magnetometer reading's reference vector
    (:func:`declination_turn`), so that they are scored against the north
    they estimate, not geographic north (on the ground the two differ by the
    site's declination)."""

    #: The turn, once learnt (None: none, or not yet).
    _turn = None
    _turn_learnt = False

    def learn_frame(self, reference) -> bool:
        """Take the turn from a field reference ``reference`` the first time
        one comes; True if it turned the frame now."""
        if self._turn_learnt or reference is None:
            return False
        self._turn_learnt, self._turn = True, declination_turn(reference)
        return self._turn is not None

    def in_reference_frame(self, q: np.ndarray) -> np.ndarray:
        """An estimate in the magnetic frame, in the reference frame."""
        return q if self._turn is None else quat_multiply(self._turn, q)


class ComplementaryFilter(MagneticFrame, AttitudeEstimator):
    """What Madgwick's and Mahony's filters share: an NWU state (magnetic
    north) started from ``initial_attitude`` (body → ENU), the acc/mag
    readings of each step, the ENU estimate out (turned by the declination,
    :class:`MagneticFrame`)."""

    uses_vector_readings = True
    #: Their step corrects with both readings (the MARG update), or with the
    #: accelerometer's alone (the IMU update: the inclination, no heading).
    reads = frozenset({sensing.ACCELEROMETER, sensing.MAGNETOMETER})
    needs = (frozenset({sensing.ACCELEROMETER}),)

    def _set_rate_timing(self, rate_timing: str) -> None:
        self.rate_timing = one_of("rate_timing", rate_timing, RATE_TIMINGS)

    def reset(self) -> None:
        self._turn, self._turn_learnt = None, False
        self._started = False
        self._start_from(self.initial_attitude)

    def _start_from(self, q_reference) -> None:
        """The NWU state of the estimate ``q_reference`` (body → reference)."""
        q = q_reference if self._turn is None else \
            quat_multiply(quat_conjugate(self._turn), q_reference)
        q = quat_multiply(ENU_TO_NWU, q)
        self.q_nwu = tuple(float(x) for x in q / np.linalg.norm(q))

    def learn_frame(self, reference) -> bool:
        """:meth:`MagneticFrame.learn_frame`; the state re-expressed in the
        turned frame, so that the estimate goes on where it was."""
        estimate = self.attitude
        if super().learn_frame(reference):
            self._start_from(estimate)
            return True
        return False

    @property
    def attitude(self) -> np.ndarray:
        return self.in_reference_frame(quat_multiply(NWU_TO_ENU, np.array(self.q_nwu)))

    def state_is_finite(self) -> bool:
        return bool(np.isfinite(self.q_nwu).all())

    def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()) -> np.ndarray:
        acc, mag = acc_mag(vectors)
        if mag is not None:
            self.learn_frame(field_reference(vectors))
        rate = tuple(float(x) for x in omega_meas_radps) if self.takes_next_rate else NO_READING
        self._started = True
        self.update(rate, acc or NO_READING, mag or NO_READING)
        return self.attitude

    @property
    def takes_next_rate(self) -> bool:
        """Whether the next step integrates its rate: every step but, with
        ``rate_timing = "end"``, the first (module docstring)."""
        return self._started or self.rate_timing == "workshop"


class Madgwick(ComplementaryFilter):
    """Madgwick's filter (module docstring), gain ``beta`` (rad/s)."""

    name = "madgwick"
    label = "Madgwick"
    halved_field = False
    tunable = (Tunable("beta", "log", (1e-6, 10.0), span=1.0,
                       description="the gradient step's gain (rad/s)"),)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY, beta: float = 0.1,
                 rate_timing: str = "workshop", on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        self._set_rate_timing(rate_timing)
        self.beta = finite_number("beta", beta, minimum=0.0)
        self.reset()

    def update(self, gyro, acc, mag) -> None:
        self.q_nwu = madgwick_step(self.q_nwu, gyro, acc, mag, self.beta, self.dt,
                                   self.halved_field)


class MadgwickBROAD(Madgwick):
    """Madgwick's C code as the BROAD authors ran it: the field's reference
    halved (module docstring). For reproducing their numbers, not for use."""

    name = "madgwick-broad"
    label = "Madgwick (BROAD's C code)"
    halved_field = True


class Mahony(ComplementaryFilter):
    """Mahony's explicit complementary filter (module docstring): gains
    ``kp`` (1/s) and ``ki`` (1/s²) on the alignment error."""

    name = "mahony"
    label = "Mahony"
    tunable = (Tunable("kp", "log", (1e-6, 100.0), span=1.0,
                       description="the proportional gain (1/s)"),
               Tunable("ki", "log", (1e-12, 10.0), span=1.0,
                       description="the integral gain (1/s²)"))

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY, kp: float = 0.5,
                 ki: float = 0.001, rate_timing: str = "workshop", on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        self._set_rate_timing(rate_timing)
        self.kp = finite_number("kp", kp, minimum=0.0)
        self.ki = finite_number("ki", ki, minimum=0.0)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.integral = (0.0, 0.0, 0.0)

    def update(self, gyro, acc, mag) -> None:
        self.q_nwu, self.integral = mahony_step(self.q_nwu, self.integral, gyro, acc, mag,
                                                self.kp, self.ki, self.dt)
