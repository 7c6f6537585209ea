"""Whole records: an estimator run over one, or tracked through it.

:meth:`RecordRuns.run` resets the estimator and steps it through a record,
returning its ``(N, 4)`` estimates; :meth:`RecordRuns.track` also keeps, at
every step, the covariance and gyro bias estimate and the star tracker's
normalised innovation squared, in an :class:`EstimateTrace`. Numpy's
overflow warnings are silenced over a record (:func:`quiet_overflow`):
divergence is detected and reported by the step itself
(:mod:`estimators.stepping`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.readings import checked_vector_record, observations_at


class RecordRuns:
    """Running an estimator over a record (mixed into
    :class:`~estimators.base.AttitudeEstimator`, whose ``step`` and
    per-run counts these use)."""

    def run(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
            available: np.ndarray, offset_s: np.ndarray | None = None, *,
            vectors=None, progress=None) -> np.ndarray:
        """Reset, then step through a whole record; returns ``(N, 4)`` estimates.

        Parameters
        ----------
        omega_meas_radps : (N, 3) array, rad/s
        star_tracker_quat : (N, 4) array, the held star tracker output
        available : (N,) bool array, True where a new reading was taken
        offset_s : (N,) array, optional
            Seconds after ``t_k`` each step's reading was taken (off the gyro
            grid; see :meth:`step`); zeros if None.
        vectors : sequence of :class:`sensors.vector.VectorReadings`, optional
            Each vector sensor's readings over the record (``(N, 3)`` rows).
        progress : a progress bar (``update(n)``), optional
            Advanced by one per step (every :data:`PROGRESS_EVERY` steps).
        """
        omega, star, available, offsets = self._start_record(
            omega_meas_radps, star_tracker_quat, available, offset_s)
        vectors = checked_vector_record(vectors, len(omega))
        estimates = np.empty((len(omega), 4))
        with quiet_overflow():
            for k in range(len(omega)):
                estimates[k] = self.step(omega[k], star[k] if available[k] else None,
                                         offsets[k], observations_at(vectors, k))
                _advance(progress, k, len(omega))
        return estimates

    def track(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
              available: np.ndarray, offset_s: np.ndarray | None = None, *,
              vectors=None, progress=None) -> "EstimateTrace":
        """Like :meth:`run`, also collecting the covariance and bias estimate
        of every step (None where the estimator keeps none) and the steps of
        readings rejected by gating."""
        omega, star, available, offsets = self._start_record(
            omega_meas_radps, star_tracker_quat, available, offset_s)
        vectors = checked_vector_record(vectors, len(omega))
        n = len(omega)
        quat = np.empty((n, 4))
        columns = {"attitude_covariance": None, "bias_radps": None, "bias_covariance": None}
        nis, nis_dof = None, None
        with quiet_overflow():
            for k in range(n):
                skipped, rejections = self.skipped["reading"], len(self.rejections)
                quat[k] = self.step(omega[k], star[k] if available[k] else None, offsets[k],
                                    observations_at(vectors, k))
                used = (available[k] and self.skipped["reading"] == skipped
                        and ("star_tracker" not in (sensor for _, sensor in
                                                    self.rejections[rejections:])))
                innovation = self.innovation_nis if used and self.diverged_step is None else None
                if innovation is not None:
                    if nis is None:
                        nis, nis_dof = np.full(n, np.nan), self.innovation_dof
                    nis[k] = innovation
                self._collect(columns, k, n)
                if nis is not None and self.diverged_step is not None:
                    nis[k] = np.nan
                _advance(progress, k, n)
        rejected = {}
        for k, sensor in self.rejections:
            rejected.setdefault(sensor, []).append(k)
        return EstimateTrace(quat=quat, **columns, nis=nis, nis_dof=nis_dof,
                             rejected={sensor: np.array(steps) for sensor, steps in
                                       rejected.items()})

    def _collect(self, columns: dict, k: int, n: int) -> None:
        """Step ``k``'s covariance and bias estimate into ``columns`` (NaN once diverged)."""
        for key in columns:
            value = getattr(self, key)
            if value is None:
                continue
            if columns[key] is None:
                columns[key] = np.empty((n,) + np.shape(value))
            columns[key][k] = value if self.diverged_step is None else np.nan


#: A record's progress bar is advanced this many steps at a time.
PROGRESS_EVERY = 1000


def _advance(progress, k: int, n: int) -> None:
    """Advance ``progress`` after step ``k`` of ``n`` (every
    :data:`PROGRESS_EVERY` steps and at the last; a bar's update costs
    microseconds, a step of a filter tens)."""
    if progress is not None and ((k + 1) % PROGRESS_EVERY == 0 or k + 1 == n):
        progress.update((k % PROGRESS_EVERY) + 1)


def quiet_overflow():
    """No numpy warnings over a record: overflow on the way to divergence is
    what :meth:`~estimators.base.AttitudeEstimator.step` detects and reports,
    once (entered per record, not per step: it costs about 1.5 µs)."""
    return np.errstate(over="ignore", invalid="ignore", divide="ignore")


@dataclass(frozen=True)
class EstimateTrace:
    """An estimator's outputs over a record of ``N`` steps.

    Attributes
    ----------
    quat : (N, 4) estimates, scalar-first
    attitude_covariance : (N, 3, 3) rad², or None
    bias_radps : (N, 3) rad/s, or None
    bias_covariance : (N, 3, 3) (rad/s)², or None
    nis : (N,) the normalised innovation squared at reading steps (NaN
        elsewhere), or None
    nis_dof : its degrees of freedom, or None
    rejected : sensor name → steps of readings rejected by gating
    """

    quat: np.ndarray
    attitude_covariance: np.ndarray | None = None
    bias_radps: np.ndarray | None = None
    bias_covariance: np.ndarray | None = None
    nis: np.ndarray | None = None
    nis_dof: int | None = None
    #: sensor → the steps whose reading innovation gating rejected (empty without gating).
    rejected: dict = field(default_factory=dict)
