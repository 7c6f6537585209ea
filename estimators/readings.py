"""The measurements an estimator is fed, checked where they enter.

:meth:`~estimators.base.AttitudeEstimator.step` takes one step's gyro rate
(rad/s), star tracker reading (a quaternion), the reading's offset within
the step (s) and vector readings; ``run`` and ``track`` take whole records.
A record's shapes are checked once (:meth:`MeasurementChecks._start_record`,
:func:`checked_vector_record`), each step's values as the step takes them. A
measurement that cannot be used raises :class:`InvalidMeasurementError`,
naming the step, the value and the rule, or, under ``on_invalid="skip"``, is
treated as missing and counted in ``skipped``. The readings offered to an
estimator are counted here too, for :meth:`MeasurementChecks.readings_used`.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.validation import MAX_MEASURED_RATE_RADPS, InvalidParameterError


class InvalidMeasurementError(InvalidParameterError):
    """A measurement an estimator cannot use; the message names the step,
    the value and the rule."""


class MeasurementChecks:
    """The checks of an estimator's measurements and the count of its
    readings (mixed into :class:`~estimators.base.AttitudeEstimator`, whose
    ``dt``, ``on_invalid``, ``reads`` and per-run counts these use)."""

    def _checked_rate(self, omega_meas_radps) -> np.ndarray:
        """The step's rate, or the last good one under ``on_invalid="skip"``."""
        omega = _real_array("omega_meas_radps", omega_meas_radps, strict=False)
        if omega.shape != (3,) or not math.isfinite(omega[0] + omega[1] + omega[2]):
            return self._invalid("rate", "omega_meas_radps", omega_meas_radps,
                                 "must be 3 finite numbers (rad/s)", self._last_rate)
        if max(abs(omega[0]), abs(omega[1]), abs(omega[2])) > MAX_MEASURED_RATE_RADPS:
            return self._invalid("rate", "omega_meas_radps", omega_meas_radps,
                                 f"each component must be within ±{MAX_MEASURED_RATE_RADPS:g} "
                                 "rad/s (beyond any spacecraft or hand-held IMU)",
                                 self._last_rate)
        self._last_rate = omega
        return omega

    def _checked_reading(self, star_tracker_quat):
        """The step's reading, or None under ``on_invalid="skip"``."""
        reading = _real_array("star_tracker_quat", star_tracker_quat, strict=False)
        norm2 = reading @ reading if reading.shape == (4,) else math.nan
        if not (math.isfinite(norm2) and norm2 > 1e-24):
            return self._invalid("reading", "star_tracker_quat", star_tracker_quat,
                                 "must be 4 finite numbers of non-zero norm", None)
        return star_tracker_quat

    def _checked_vectors(self, vectors) -> tuple:
        """The step's usable vector readings (a bad one raises, or is skipped and counted)."""
        if hasattr(vectors, "body"):        # one reading, not a sequence of them
            raise InvalidMeasurementError(f"vectors at step {self.step_index}", vectors,
                                          "must be a sequence of VectorObservation (one "
                                          "reading goes in a list: [observation])")
        kept = []
        for observation in vectors:
            body = _real_array("vector body", getattr(observation, "body", None), strict=False)
            reference = _real_array("vector reference", getattr(observation, "reference", None),
                                    strict=False)
            variance = getattr(observation, "variance", math.nan)
            if isinstance(variance, (bool, np.bool_)) or \
                    not isinstance(variance, (int, float, np.integer, np.floating)):
                variance = math.nan         # text, None: no variance
            if (body.shape == (3,) and reference.shape == (3,)
                    and np.all(np.isfinite(body)) and np.all(np.isfinite(reference))
                    and reference @ reference > 0 and math.isfinite(variance) and variance > 0):
                kept.append(observation)
                continue
            self._invalid("vector", f"vector reading of {getattr(observation, 'sensor', '?')}",
                          observation, "must have 3 finite numbers in body and reference (a "
                          "non-zero reference) and a variance > 0", None)
        return tuple(kept)

    def _checked_offset(self, offset_s) -> float:
        """A reading's offset after its step's time: in ``[0, dt)``."""
        try:
            offset = float(offset_s)
        except (TypeError, ValueError):
            offset = math.nan
        if not 0.0 <= offset < self.dt:
            raise InvalidMeasurementError(f"offset_s at step {self.step_index - 1}", offset_s,
                                          f"must be in [0, dt = {self.dt:g}) seconds")
        return offset

    def _invalid(self, kind, name, value, rule, replacement):
        if self.on_invalid == "raise":
            raise InvalidMeasurementError(f"{name} at step {self.step_index}", value, rule)
        self.skipped[kind] += 1
        return replacement

    def _start_record(self, omega_meas_radps, star_tracker_quat, available, offset_s=None):
        """Reset, and check a whole record's shapes: ``(N, 3)`` rates, ``(N, 4)``
        readings, ``(N,)`` booleans and ``(N,)`` offsets, one row per step
        (values are checked step by step, in :meth:`step`)."""
        self.reset()
        self._restart_count()
        omega = checked_rates(omega_meas_radps)
        star = _real_array("star_tracker_quat", star_tracker_quat)
        flags = np.asarray(available)
        n = len(omega)
        offsets = np.zeros(n) if offset_s is None else _real_array("offset_s", offset_s)
        for name, array, shape in (("star_tracker_quat", star, (n, 4)),
                                   ("available", flags, (n,)), ("offset_s", offsets, (n,))):
            if array.shape != shape:
                raise InvalidMeasurementError(f"{name} of shape", array.shape, f"must have "
                                              f"shape {shape}: one row per step, as the rates")
        if flags.dtype != bool:
            raise InvalidMeasurementError("available", flags, "must be booleans (True where "
                                          "a reading was taken)")
        return omega, star, flags, offsets

    def _count_offered(self, star_tracker_quat, vectors) -> None:
        """Count the step's readings of the sensors this estimator reads."""
        reads, offered = self.reads, self.offered
        if star_tracker_quat is not None and (reads is None or "star_tracker" in reads):
            offered["star_tracker"] = offered.get("star_tracker", 0) + 1
        for observation in vectors:
            sensor = observation.sensor
            if reads is None or sensor in reads:
                offered[sensor] = offered.get(sensor, 0) + 1

    def readings_used(self) -> int:
        """How many of the readings offered since the last reset it applied:
        those offered (:attr:`offered`) but those gating rejected
        (:attr:`rejected`). Zero with readings offered means its estimate
        was the gyro's alone (a static solver that never solved overrides it)."""
        return sum(self.offered.values()) - sum(self.rejected.values())


def observations_at(vectors, k: int) -> tuple:
    """Step ``k``'s vector readings: each sensor's ``observation(k)`` where it
    is ``available`` (:class:`sensors.vector.VectorReadings`, duck-typed:
    estimators do not import sensors), or ()."""
    if not vectors:
        return ()
    return tuple(readings.observation(k) for readings in vectors if readings.available[k])


def checked_rates(omega_meas_radps) -> np.ndarray:
    """A record's gyro rates as a float array of shape ``(N, 3)``, one row
    per step, or refused in one line (its values are checked where a
    filter reads them): the one rule of every path that takes a whole record."""
    omega = _real_array("omega_meas_radps", omega_meas_radps)
    if omega.ndim != 2 or omega.shape[1:] != (3,):
        raise InvalidMeasurementError("omega_meas_radps of shape", omega.shape,
                                      "must have shape (N, 3): one row per step")
    return omega


def checked_vector_record(vectors, n_steps: int) -> tuple:
    """A record's vector readings: each sensor's arrays one row per step."""
    if vectors is None:
        return ()
    if hasattr(vectors, "body"):            # one sensor's readings, not a sequence of them
        raise InvalidMeasurementError("vectors", type(vectors).__name__, "must be a sequence "
                                      "of VectorReadings, one per sensor (one sensor's go in "
                                      "a list: [readings])")
    vectors = tuple(vectors)
    for readings in vectors:
        for name, shape in (("body", (n_steps, 3)), ("reference", (n_steps, 3)),
                            ("available", (n_steps,)), ("variance", (n_steps,))):
            array = np.asarray(getattr(readings, name, None))
            if array.shape != shape:
                raise InvalidMeasurementError(f"vectors[{getattr(readings, 'sensor', '?')}]."
                                              f"{name} of shape", array.shape,
                                              f"must have shape {shape}: one row per step")
    return vectors


def _real_array(name: str, value, strict: bool = True) -> np.ndarray:
    """``value`` as a float array. Complex, boolean, string or object data are
    refused (numpy would drop an imaginary part, or fail deep inside a
    filter); with ``strict=False`` they come back as an empty array, which
    the caller's shape check then refuses with its own rule."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):      # ragged lists
        array = np.asarray(None)
    if array.dtype.kind in "iuf":
        return array.astype(float, copy=False)
    if not strict:
        return np.empty(0)
    raise InvalidMeasurementError(name, value, "must be real numbers (not complex, booleans, "
                                  "text or None: NaN for a missing one)")
