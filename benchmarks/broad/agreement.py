"""Scores without a reference: each estimator against the median attitude
of the others.

A recording without a reference has no truth to score against; what can be
measured is how far each estimator's attitude is, sample by sample, from
the median attitude of the other estimators that observe the heading (the
*consensus*; the estimator itself left out, so that it cannot pull the
consensus towards itself; the median, so that one estimator far off moves
it little). That is **agreement, not accuracy**: filters that share a
model share its errors and agree on them, and an estimator better than
all the others disagrees with them by its own advantage. The tables say
so wherever these numbers are shown, and on BROAD, where both can be
measured, the README compares the ranking by agreement with the ranking by
the reference.

The mean of unit quaternions is the chordal L2 mean of Markley, Cheng,
Crassidis & Oshman ("Averaging quaternions", *J. Guidance, Control, and
Dynamics* 30 (4), 2007): the eigenvector of the largest eigenvalue of
:math:`\\sum_i q_i q_i^T`, sign-free. scipy's ``Rotation.mean`` computes it
for one set of rotations; here it is batched over the samples (one
``eigh`` of an (N, 4, 4) stack instead of N calls). The median
(:func:`median_attitudes`) starts from it and reweights it (Weiszfeld).
"""
from __future__ import annotations

import numpy as np

from benchmarks.broad.metric import errors_deg, rmse_of

#: The per-trial columns of the scores against the others' median attitude.
AGREEMENT = ("agreement_total_deg", "agreement_heading_deg", "agreement_inclination_deg")
#: What the agreement scores are taken against, in words (tables, notes).
AGAINST = "the median attitude of the other estimators that observe the heading"
#: The same where none does (no magnetometer): their attitudes, headings off.
AGAINST_LEVELLED = "the median attitude of the other estimators, each heading taken off"
#: Weiszfeld's iterations for the median at most (it stops when no
#: estimate moves by MEDIAN_TOLERANCE), and the least distance a member is
#: weighted by (a member at the estimate would weigh infinitely).
MEDIAN_ITERATIONS = 100
MEDIAN_TOLERANCE = 1e-6
MEDIAN_FLOOR = 1e-6


def mean_attitudes(quaternions: np.ndarray) -> np.ndarray:
    """``(N, 4)``: per sample, the chordal mean of ``quaternions`` ``(K, N,
    4)`` (scalar first) over its finite members; NaN where none is finite."""
    finite = np.isfinite(quaternions).all(axis=2)
    members = np.moveaxis(np.where(finite[..., None], quaternions, 0.0), 0, 1)   # (N, K, 4)
    _, vectors = np.linalg.eigh(np.matmul(members.transpose(0, 2, 1), members))
    return _canonical(vectors[:, :, -1], finite)


def median_attitudes(quaternions: np.ndarray) -> np.ndarray:
    """``(N, 4)``: per sample, the attitude nearest all of ``quaternions``
    in the sum of chordal distances (not of their squares), so that one
    estimator far off moves it little: Weiszfeld's iteration (Hartley,
    Aftab & Trumpf, "L1 rotation averaging using the Weiszfeld algorithm",
    CVPR 2011) from the mean (:func:`mean_attitudes`, whose sign needs no
    member to be right): ``v ← Σ s q / d`` normalised, each member ``q`` turned to
    the estimate's sign ``s`` and weighted by the inverse of its chordal
    distance ``d`` to the last estimate ``v`` — the stationary point of the
    sum of distances on the unit sphere. A step costs two sums over the
    members."""
    finite = np.isfinite(quaternions).all(axis=2)
    members = np.where(finite[..., None], quaternions, 0.0)
    estimate = np.nan_to_num(mean_attitudes(quaternions))
    active = np.arange(len(estimate))           # the samples still moving
    for _ in range(MEDIAN_ITERATIONS):
        part, last = members[:, active], estimate[active]
        cosine = np.einsum("kni,ni->kn", part, last)
        distance = np.sqrt(np.maximum(2.0 - 2.0 * np.minimum(np.abs(cosine), 1.0), 0.0))
        weights = np.where(finite[:, active], np.sign(cosine) /
                           np.maximum(distance, MEDIAN_FLOOR), 0.0)
        step = np.einsum("kn,kni->ni", weights, part)
        step /= np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-300)
        estimate[active] = step
        active = active[np.max(np.abs(step - last), axis=1) >= MEDIAN_TOLERANCE]
        if not active.size:
            break
    return _canonical(estimate, finite)


def _canonical(quaternions: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """Scalar part non-negative; NaN where no member was finite."""
    quaternions = quaternions * np.where(quaternions[:, 0:1] < 0, -1.0, 1.0)
    quaternions[~finite.any(axis=0)] = np.nan
    return quaternions


def agreement_scores(estimates: dict, members, heading=None) -> tuple[dict, dict]:
    """``(scores, curves)``: for each estimator of ``estimates`` (name →
    ``(N, 4)``), its total, heading and inclination RMS (°) against the
    median of ``members`` other than itself (:data:`AGREEMENT`; NaN where no
    other member is), and its error against that median over time: the
    total, or for an estimator not in ``heading`` (those that observe it;
    default: every one) the inclination alone, its total and heading NaN,
    as against the reference."""
    scores, curves = {}, {}
    for name, estimate in estimates.items():
        others = [estimates[other] for other in members if other != name]
        if not others:
            scores[name] = dict.fromkeys(AGREEMENT, float("nan"))
            curves[name] = np.full(len(estimate), np.nan)
            continue
        consensus = median_attitudes(np.stack(others))
        errors = errors_deg(estimate, consensus)
        rms = rmse_of(errors, estimate, consensus, np.ones(len(estimate), dtype=bool))
        scores[name] = {column: rms[f"{part}_rmse_deg"]
                        for column, part in zip(AGREEMENT, ("total", "heading", "inclination"))}
        observed = heading is None or name in heading
        if not observed:
            scores[name].update(dict.fromkeys(AGREEMENT[:2], float("nan")))
        curves[name] = errors["total" if observed else "inclination"]
    return scores, curves
