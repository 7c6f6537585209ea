"""Summary statistics of an attitude error history (the workshop model, "What is measured").

The workshop's loss is the sample standard deviation (``ddof = 1``) of the
error over all ``N`` samples; the other statistics are reported beside it.
All in degrees.
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import attitude_error_rad, quat_conjugate, quat_multiply

#: Arcseconds per degree.
ARCSEC_PER_DEG = 3600.0
#: Angles of this size (degrees) and below are shown in arcseconds, above in degrees.
ARCSEC_BELOW_DEG = 0.1


def angle_unit(typical_deg: float) -> tuple[float, str]:
    """``(scale from degrees, unit)`` for angles of about ``typical_deg``:
    arcseconds below :data:`ARCSEC_BELOW_DEG`, degrees otherwise (one unit
    per table or axis)."""
    return (ARCSEC_PER_DEG, "arcsec") if typical_deg < ARCSEC_BELOW_DEG else (1.0, "deg")


#: Column names of every statistics table, in order.
STAT_COLUMNS = ("mean_deg", "median_deg", "std_deg", "three_sigma_deg", "rms_deg",
                "max_deg", "final_deg")


def attitude_error_deg(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """The workshop model's sign-invariant attitude error, degrees, for ``(..., 4)`` stacks."""
    return np.degrees(attitude_error_rad(q_true, q_est))


def inclination_error_deg(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    r"""The inclination part of the error, degrees, for ``(N, 4)`` body →
    reference stacks whose reference frame's z axis is up (a ground site's
    east-north-up): the error rotation :math:`\hat q \otimes q^{-1}` in the
    reference frame less its rotation about the vertical,
    :math:`2\arccos\sqrt{w^2 + z^2}` (Laidig et al. 2021, §4; the BROAD
    metric's inclination, :mod:`benchmarks.broad.metric`). The score of an
    estimate with no heading reference (gravity alone)."""
    error = quat_multiply(q_est, quat_conjugate(q_true))
    return np.degrees(2.0 * np.arccos(np.clip(np.hypot(error[:, 0], error[:, 3]), 0.0, 1.0)))


def error_statistics(error_deg: np.ndarray) -> dict[str, float]:
    """Mean, median, std (ddof = 1), 3σ, RMS, max and final value of ``error_deg``."""
    error = np.asarray(error_deg, dtype=float)
    std = float(np.std(error, ddof=1)) if error.size > 1 else 0.0
    return {
        "mean_deg": float(np.mean(error)),
        "median_deg": float(np.median(error)),
        "std_deg": std,
        "three_sigma_deg": 3.0 * std,
        "rms_deg": float(np.sqrt(np.mean(error * error))),
        "max_deg": float(np.max(error)),
        "final_deg": float(error[-1]),
    }


def loss(error_deg: np.ndarray) -> float:
    """The workshop's loss: sample standard deviation of the error, degrees."""
    return error_statistics(error_deg)["std_deg"]


def nees(errors: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """``eᵀ P⁻¹ e`` for stacks of errors ``(..., n)`` and covariances ``(..., n, n)``:
    the normalised estimation error squared (:mod:`benchmarks.experiments.consistency`)."""
    errors = np.asarray(errors, dtype=float)
    solved = np.linalg.solve(np.asarray(covariances, dtype=float), errors[..., None])[..., 0]
    return np.sum(errors * solved, axis=-1)
