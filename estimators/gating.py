"""Which readings a filter applies, and the innovations it logs.

Two tests refuse a reading before its update: the χ² gate on its
normalised innovation squared (:meth:`InnovationGate.accepts`, with
``gate_probability``) and the magnetic disturbance test on a
magnetometer's magnitude (:meth:`InnovationGate.passes_norm`, with
``magnetic_norm_tolerance``). Rejected readings are counted, by sensor and
step. With ``log_innovations``, the NIS and ``ln det S`` of every reading
that reaches the gate are summed (:attr:`InnovationGate.innovation_sums`),
the likelihood a tuner maximises: a rejected reading's NIS taken at the
gate's threshold. Summed over the applied updates alone, the likelihood per
update rewards settings that reject what fits badly; at the gate, a
rejected reading costs what the worst accepted one may (a robust,
Huber-like likelihood of every reading; a tuner also bounds the readings
refused otherwise: :data:`benchmarks.broad.tuning.REFUSAL_TOLERANCE`). The
checks of the two settings are here too.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from dynamics.validation import InvalidParameterError, finite_number


class InnovationGate:
    """Innovation gating and logging for the filters (mixed into
    :class:`~estimators.base.KalmanEstimator` before
    :class:`~estimators.base.AttitudeEstimator`, whose per-run counts these
    extend: ``rejected``, ``rejections``)."""

    #: The χ² probability of innovation gating, or None (off; see :meth:`accepts`).
    gate_probability = None

    #: Magnetic disturbance detection: a magnetometer reading whose
    #: magnitude is off its reference's by more than this fraction is
    #: rejected before any update (None: no test). See :meth:`passes_norm`.
    magnetic_norm_tolerance = None

    def passes_norm(self, observation) -> bool:
        r"""Whether a vector reading passes the magnetic disturbance test,
        :math:`\bigl|\,\lVert b\rVert / \lVert r\rVert - 1\bigr| \le`
        :attr:`magnetic_norm_tolerance` (magnetometers only; always, when it
        is None). A disturbed field (a magnet, steel nearby) changes its
        magnitude; its direction alone can pass the χ² gate while it pulls
        the heading away (VQF's detector tests the magnitude and the dip;
        Laidig & Seel 2023, §3.3). Rejected readings are counted as the
        gate counts them."""
        tolerance = self.magnetic_norm_tolerance
        if tolerance is None or observation.sensor != "magnetometer":
            return True
        b0, b1, b2 = np.asarray(observation.body, dtype=float).tolist()
        r0, r1, r2 = np.asarray(observation.reference, dtype=float).tolist()
        ratio = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2) / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if abs(ratio - 1.0) <= tolerance:
            return True
        self._reject(observation.sensor)
        return False

    def _reject(self, sensor: str) -> None:
        """Count a rejected reading of ``sensor`` at this step."""
        self.rejected[sensor] = self.rejected.get(sensor, 0) + 1
        self.rejections.append((self.step_index - 1, sensor))

    def accepts(self, y: np.ndarray, S: np.ndarray, dof: int, sensor: str) -> bool:
        r"""Innovation gating: whether a reading of innovation ``y`` and
        innovation covariance ``S`` passes the χ² test of its NIS,
        :math:`y^\mathsf{T} S^{-1} y \le \chi^2_{\text{dof}}(p)` with ``p`` the
        :attr:`gate_probability` (always, when it is None). A rejected reading
        is counted in :attr:`rejected` and is not applied: spacecraft reject
        albedo and glints this way, ground IMUs magnetic disturbances and
        linear acceleration."""
        if self.gate_probability is None:
            return True
        nis = float(y @ np.linalg.solve(S, y))
        threshold = gate_threshold(self.gate_probability, dof)
        if nis <= threshold:
            return True
        self._reject(sensor)
        if self.log_innovations:
            self._fold_innovation(threshold, S)
        return False

    #: The star tracker update's (y, S) on a step whose vector updates followed it.
    _tracker_innovation = None
    #: Set True before a run to sum each gated reading's innovation terms
    #: in :attr:`innovation_sums` (the tuner's likelihood objective).
    log_innovations = False

    def _restart_count(self) -> None:
        super()._restart_count()
        #: With :attr:`log_innovations`: the readings that reached the gate
        #: since the run began (star tracker and vector readings alike,
        #: applied or rejected), the sum of their NIS yᵀ S⁻¹ y (a rejected
        #: one's at the gate's threshold) and of their ln det S. The
        #: innovations' negative log-likelihood is half the two sums plus a
        #: constant.
        self.innovation_sums = {"updates": 0, "nis": 0.0, "log_det": 0.0}

    def _log_innovation(self, rejections: int) -> None:
        """Fold the update just made into :attr:`innovation_sums`, unless
        gating rejected it (:meth:`accepts` folded it then) (``rejections``: their count before it)."""
        if len(self.rejections) != rejections:
            return
        kept = getattr(self, "filter", self)
        y, S = np.ravel(kept.y), np.atleast_2d(kept.S)
        self._fold_innovation(float(y @ np.linalg.solve(S, y)), S)

    def _fold_innovation(self, nis: float, S: np.ndarray) -> None:
        """Add a reading's ``nis`` and ln det ``S`` to :attr:`innovation_sums`."""
        sign, log_det = np.linalg.slogdet(np.atleast_2d(S))
        sums = self.innovation_sums
        sums["updates"] += 1
        sums["nis"] += nis if sign > 0 else math.inf
        sums["log_det"] += float(log_det) if sign > 0 else math.inf


@lru_cache(maxsize=64)
def gate_threshold(probability: float, dof: int) -> float:
    """The χ² quantile a reading's NIS must not exceed to pass the gate."""
    from scipy.stats import chi2
    return float(chi2.ppf(probability, dof))


def gate_probability_setting(value) -> float | None:
    """A gating probability: None (off) or within (0, 1)."""
    if value is None:
        return None
    probability = finite_number("gate_probability", value)
    if not 0.0 < probability < 1.0:
        raise InvalidParameterError("gate_probability", value, "must be within 0 and 1 "
                                    "(e.g. 0.9999), or None for no gating")
    return probability


def norm_tolerance_setting(value) -> float | None:
    """A magnetic norm tolerance: None (off) or a fraction > 0."""
    if value is None:
        return None
    return finite_number("magnetic_norm_tolerance", value, strictly_positive=True)

