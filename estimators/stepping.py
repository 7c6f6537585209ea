"""The step every estimator takes, and how it detects divergence.

:meth:`StepTemplate.step` is the template: it checks the step's
measurements (:mod:`estimators.readings`), hands them to the estimator's own
:meth:`~StepTemplate._step` (or :meth:`~StepTemplate._step_at`, for a
reading taken between two gyro steps), and checks what comes back. An
estimate that is not a unit quaternion is a defect of the estimator
(:class:`InvalidEstimateError`); an estimate or state that is no longer
finite (:func:`finite_state`, :meth:`~StepTemplate.state_is_finite`) means
the estimator has *diverged*: that step's estimate and every later one is
NaN, so a diverged run never scores as a number.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.validation import InvalidParameterError


class InvalidEstimateError(InvalidParameterError):
    """An estimator returned something that is not an attitude (a quaternion
    off the unit sphere, or not four numbers): a defect of that estimator."""


#: How far ``|q|²`` of an estimate may be from 1: far above the rounding of
#: a normalisation (1e-16), far below any quaternion a filter would output.
UNIT_NORM_TOLERANCE = 1e-6


class StepTemplate:
    """The step of every estimator (mixed into
    :class:`~estimators.base.AttitudeEstimator`): subclasses implement
    :meth:`_step`; the measurement checks are
    :class:`~estimators.readings.MeasurementChecks`'."""

    #: Whether :meth:`_step_at` applies a reading at its own time (a reading
    #: off the gyro grid); if not, such a reading is applied at its step.
    applies_reading_times = False

    def step(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray | None = None,
             offset_s: float = 0.0, vectors=()) -> np.ndarray:
        """Consume step ``k``'s measurements and return ``q̂[k]`` as a ``(4,)`` array.

        Measurements are checked here, where they enter: a rate that is not 3
        finite numbers, or a reading that is not 4 finite numbers of non-zero
        norm, or a rate beyond
        ±:data:`~dynamics.validation.MAX_MEASURED_RATE_RADPS`, raises
        :class:`~estimators.readings.InvalidMeasurementError` naming the step
        and the value, or,
        with ``on_invalid="skip"``, is treated as missing (the last good rate
        is held; the reading is ignored) and counted in :attr:`skipped`.
        A step whose estimate or state is not finite (see
        :meth:`state_is_finite`) marks the estimator diverged: that step's
        estimate and every later one is NaN. Subclasses implement :meth:`_step`.

        Parameters
        ----------
        omega_meas_radps : (3,) array
            Gyro reading at step ``k``, rad/s, body frame.
        star_tracker_quat : (4,) array or None
            The star tracker's reading if one was taken at step ``k``
            (``available[k]``), else None.
        offset_s : float
            When the reading was taken, seconds after ``t_k`` (``0 <= τ < dt``;
            0 on the gyro grid). With ``τ > 0`` the estimate of ``t_k`` comes
            first, without the reading; the reading is applied at its own time
            by estimators that can (:attr:`applies_reading_times`:
            propagate to ``t_k + τ``, update, propagate on to ``t_{k+1}``).
        vectors : sequence of :class:`sensors.vector.VectorObservation`
            The vector readings taken at ``t_k`` (applied, in order, after the
            star tracker's, by estimators with :attr:`uses_vector_readings`;
            ignored by the others). One whose vectors are not 3 finite
            numbers (a zero reference) or whose variance is not > 0 is refused
            like a bad reading (or, with ``"skip"``, counted in ``skipped["vector"]``).
        """
        omega = self._checked_rate(omega_meas_radps)
        if star_tracker_quat is not None:
            star_tracker_quat = self._checked_reading(star_tracker_quat)
        if vectors:
            vectors = self._checked_vectors(vectors) if self.uses_vector_readings else ()
        self.step_index += 1
        if self.diverged_step is not None:
            return np.full(4, np.nan)
        self._count_offered(star_tracker_quat, vectors)
        estimate = self._guarded_step(omega, star_tracker_quat, offset_s, vectors)
        if estimate is None or not (finite_state(estimate) and self.state_is_finite()):
            self.diverged_step = self.step_index - 1
            return np.full(4, np.nan)
        return self._checked_estimate(estimate)

    def _guarded_step(self, omega, star_tracker_quat, offset_s, vectors):
        """The estimator's own step on checked measurements, or None where it
        broke down (a covariance no longer positive definite; a non-finite
        matrix scipy refused), which :meth:`step` records as divergence."""
        try:
            if offset_s and star_tracker_quat is not None:
                offset = self._checked_offset(offset_s)
                estimate = (self._step_at(omega, star_tracker_quat, offset, vectors) if vectors
                            else self._step_at(omega, star_tracker_quat, offset))
            elif vectors:
                estimate = self._step(omega, star_tracker_quat, vectors)
            else:
                estimate = self._step(omega, star_tracker_quat)
        except np.linalg.LinAlgError:      # a covariance no longer positive definite
            estimate = None
        except ValueError:                 # scipy refusing a non-finite matrix
            if self.state_is_finite():
                raise
            estimate = None
        return estimate

    def _step(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray | None,
              vectors=()) -> np.ndarray:
        """The estimator's own step, on checked measurements (``vectors`` only
        given to an estimator with :attr:`uses_vector_readings`)."""
        raise NotImplementedError

    def _step_at(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
                 offset_s: float, vectors=()) -> np.ndarray:
        """A step whose reading was taken ``offset_s`` after ``t_k``. This
        base applies it at the step (an estimator without a notion of time
        within a step); :attr:`applies_reading_times` estimators override it."""
        if vectors:
            return self._step(omega_meas_radps, star_tracker_quat, vectors)
        return self._step(omega_meas_radps, star_tracker_quat)

    def _checked_estimate(self, estimate) -> np.ndarray:
        """The step's estimate, if it is a unit quaternion: anything else is
        no attitude (the error metric would clip ``[10, 0, 0, 0]`` to a
        perfect 0°, and score a zero quaternion 180°), so it is refused,
        naming the class, the step and the value."""
        values = np.asarray(estimate, dtype=float).ravel().tolist()
        norm2 = math.fsum(v * v for v in values) if len(values) == 4 else math.nan
        if not abs(norm2 - 1.0) <= UNIT_NORM_TOLERANCE:
            raise InvalidEstimateError(
                f"{type(self).__name__}'s estimate at step {self.step_index - 1}", values,
                f"must be a unit quaternion (|q|^2 within {UNIT_NORM_TOLERANCE:g} of 1; "
                f"this one's is {norm2:.6g}): normalise it before returning it")
        return estimate

    def state_is_finite(self) -> bool:
        """Whether the state the next step starts from is finite (checked
        after every step; a filter also checks its covariance, see
        :func:`finite_state`). Once it is not, the estimator has *diverged*:
        :attr:`diverged_step` records the step and every estimate from that
        step on is NaN, so a diverged run never scores as a number. The
        engine's kernels make the same test at the same step."""
        return True


def finite_state(vector, covariance=None) -> bool:
    """The divergence test: ``sum(vector)`` and ``trace(covariance)`` finite
    (a NaN or infinity in either makes its sum non-finite). Summed left to
    right in Python floats, as the engine's kernels sum them, and ten times
    faster than numpy's calls on a few numbers: it runs after every step."""
    if not math.isfinite(sum(np.asarray(vector).tolist())):
        return False
    return covariance is None or math.isfinite(sum(np.diagonal(covariance).tolist()))

