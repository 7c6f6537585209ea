r"""The BROAD authors' error metric (Laidig et al. 2021, §4; their
``example_code/broad_utils.py``), exactly.

The error is the rotation between estimate and reference *in the earth
frame*, :math:`q_e = \hat q \otimes q_{ref}^{-1}` (both body → ENU). Its
total angle is :math:`2\arccos|w|`; its heading part, the rotation about
the vertical, :math:`2\arctan|z/w|`; its inclination part, what is left,
:math:`2\arccos\sqrt{w^2 + z^2}`. Each is scored as an RMS over the samples
of the movement phase, samples without a reference (NaN) left out of the
mean, as ``numpy.nanmean`` leaves them out in the authors' code. A trial's
group score is the plain mean of its trials' scores.

A trial that never moves, or has no reference during its movement, has no
sample to score (:func:`unscored_reason`): its scores are NaN, and the
tables say so and leave it out by name, never by silence.
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import quat_conjugate, quat_multiply

#: The three RMSEs, degrees, in the authors' names.
METRICS = ("total_rmse_deg", "heading_rmse_deg", "inclination_rmse_deg")
#: What a filter's own covariance claims of its heading and inclination
#: errors, each beside its RMSE (:func:`claimed_deg`).
CLAIMED = ("heading_sd_deg", "inclination_sd_deg")


def earth_error_quat(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``(N, 4)``: :math:`\\hat q \\otimes q_{ref}^{-1}`, both normalised first."""
    estimate = estimate / np.linalg.norm(estimate, axis=1, keepdims=True)
    reference = reference / np.linalg.norm(reference, axis=1, keepdims=True)
    error = quat_multiply(estimate, quat_conjugate(reference))
    return error / np.linalg.norm(error, axis=1, keepdims=True)


def total_error_rad(error: np.ndarray) -> np.ndarray:
    return 2.0 * np.arccos(np.clip(np.abs(error[:, 0]), 0.0, 1.0))


def heading_error_rad(error: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return 2.0 * np.arctan(np.abs(error[:, 3] / error[:, 0]))


def inclination_error_rad(error: np.ndarray) -> np.ndarray:
    return 2.0 * np.arccos(np.clip(np.sqrt(error[:, 0] ** 2 + error[:, 3] ** 2), 0.0, 1.0))


def without_heading(quat: np.ndarray) -> np.ndarray:
    """``(N, 4)`` attitudes (body → ENU) with their rotation about the
    vertical taken off: ``q = q_z(ψ) ⊗ q_level``, ψ = 2 atan2(z, w). The
    body's up is unchanged, so the inclination error between any two is
    too (it is the angle between their body-frame ups); what a 6-axis IMU's
    filters agree on, their headings being each its gyro's."""
    half = np.arctan2(quat[:, 3], quat[:, 0])
    zero = np.zeros_like(half)
    return quat_multiply(np.stack([np.cos(half), zero, zero, -np.sin(half)], axis=1), quat)


def errors_deg(estimate: np.ndarray, reference: np.ndarray) -> dict:
    """Total, heading and inclination error of every sample, degrees."""
    error = earth_error_quat(estimate, reference)
    return {"total": np.degrees(total_error_rad(error)),
            "heading": np.degrees(heading_error_rad(error)),
            "inclination": np.degrees(inclination_error_rad(error))}


def scored_samples(reference: np.ndarray, movement: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the samples the metric scores, those of the movement
    phase with a reference attitude."""
    return np.asarray(movement, dtype=bool) & np.isfinite(reference).all(axis=1)


def unscored_reason(movement_samples: int, scored: int) -> str | None:
    """Why a trial with ``movement_samples`` samples of movement, ``scored``
    of them with a reference, has nothing to score (None: it has)."""
    if movement_samples == 0:
        return "never moves (no sample of its movement flag is set)"
    if scored == 0:
        return f"has no reference during its movement (all {movement_samples} samples)"
    return None


def recording_unscored(recording) -> str | None:
    """Why ``recording`` (:class:`sensors.recording.Recording`) has nothing
    to score (:func:`unscored_reason`; None: it has)."""
    return unscored_reason(int(np.count_nonzero(recording.movement)), int(np.count_nonzero(
        scored_samples(recording.reference_quat, recording.movement))))


def rmse_deg(estimate: np.ndarray, reference: np.ndarray, movement: np.ndarray) -> dict:
    """:data:`METRICS` of ``estimate`` against ``reference`` over the
    ``movement`` samples (those without a reference left out)."""
    return rmse_of(errors_deg(estimate, reference), estimate, reference, movement)


def rmse_of(errors: dict, estimate: np.ndarray, reference: np.ndarray,
            movement: np.ndarray) -> dict:
    """:func:`rmse_deg` from the :func:`errors_deg` already taken. Only the
    reference's gaps are left out: an estimate that is not finite on a scored
    sample (a diverged filter) makes every score NaN, not a mean of the rest."""
    scored = scored_samples(reference, movement)
    if not scored.any() or not np.isfinite(estimate[scored]).all():
        return {metric: float("nan") for metric in METRICS}
    return {f"{key}_rmse_deg": float(np.sqrt(np.mean(error[scored] ** 2)))
            for key, error in errors.items()}


def claimed_deg(estimate: np.ndarray, covariance, reference: np.ndarray,
                movement: np.ndarray) -> dict:
    """:data:`CLAIMED`: the heading and inclination errors that the
    estimator's own attitude covariance ``covariance`` ``(N, 3, 3)`` (rad²,
    body-frame error, :math:`q = \\hat q \\otimes \\delta q(\\delta\\theta)`, as the
    MEKF keeps it; Markley & Crassidis 2014, §6.2) claims, as RMS over the
    samples the metric scores, degrees: comparable each with its RMSE, which
    a consistent filter matches. The earth-frame error's rotation about the
    vertical is :math:`u^T \\delta\\theta` to first order, with :math:`u` the
    vertical in the body frame, so the heading variance is :math:`u^T C u`
    and the tilt's mean square what is left of the trace, :math:`\\mathrm{tr}\\,C
    - u^T C u`. NaN without a covariance (a filter that keeps none, or a
    peer's library that does not give it) or where one is not finite on a
    scored sample."""
    scored = scored_samples(reference, movement)
    if covariance is None or not scored.any() or \
            not np.isfinite(covariance[scored]).all() or not np.isfinite(estimate[scored]).all():
        return {name: float("nan") for name in CLAIMED}
    from scipy.spatial.transform import Rotation
    q = estimate[scored]
    up = Rotation.from_quat(q, scalar_first=True).inv().apply([0.0, 0.0, 1.0])
    C = covariance[scored]
    heading = np.einsum("ni,nij,nj->n", up, C, up)
    tilt = np.trace(C, axis1=1, axis2=2) - heading
    return {"heading_sd_deg": float(np.degrees(np.sqrt(np.mean(heading)))),
            "inclination_sd_deg": float(np.degrees(np.sqrt(np.mean(np.maximum(tilt, 0.0)))))}
