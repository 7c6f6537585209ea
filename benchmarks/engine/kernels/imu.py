"""The IMU models (:mod:`estimators.imu`) in the engine: the per-run modules'
own functions, compiled as they are (their calls to one another turned to
the compiled twins), and the MEKF's zero-rate and heading updates with them.

Why the same functions: the models are state machines and filters whose
every branch must match the per-run class's to 1e-9; one definition, read
by both paths, cannot drift. The state of each run's models sits in
:class:`ImuState`'s arrays, read off the per-run objects after their reset.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.engine.kernels.algebra import (joseph_covariance, quat_exp, quat_times_normalized,
                                               to_body_frame)
from benchmarks.engine.kernels.twins import compiled
from estimators.imu import gravity, hard_iron, heading, lowpass, rest


coefficients = compiled(lowpass.coefficients)
_rotate = compiled(gravity.rotate)
_rotated_back = compiled(gravity.rotated_back)
_LOWPASS = {"step": compiled(lowpass.step),
            "samples_averaged": compiled(lowpass.samples_averaged)}
strapdown_step = compiled(gravity.strapdown_step)
integrate_rotation = compiled(gravity.integrate_rotation)
drift_jacobian = compiled(gravity.drift_jacobian, lowpass=_LOWPASS, rotated_back=_rotated_back)
gravity_direction = compiled(gravity.gravity_direction, lowpass=_LOWPASS,
                             rotate=_rotate,
                             rotate_back=compiled(gravity.rotate_back,
                                                  rotated_back=_rotated_back))
_reading_variance = compiled(gravity.reading_variance, lowpass=_LOWPASS)
rest_gyro_step = compiled(rest.gyro_step, lowpass=_LOWPASS)
rest_acc_step = compiled(rest.acc_step, lowpass=_LOWPASS)
field_in_reference = compiled(heading.field_in_reference, rotate=_rotate)
_close = compiled(heading._close)
_earthly = compiled(heading._earthly)
_candidate_step = compiled(heading._candidate_step, _close=_close, _earthly=_earthly)
trust_step = compiled(heading.trust_step, _candidate_step=_candidate_step, _close=_close)
steady_step = compiled(heading.steady_step, lowpass=_LOWPASS, rotate=_rotate)
validated = compiled(heading.validated)
_forget = compiled(heading.forget_heading)
_widen = compiled(heading.widen_heading)
new_trust = compiled(heading.new_state)
hard_iron_step = compiled(hard_iron.step, _take=compiled(
    hard_iron._take, _gone_step=compiled(hard_iron._gone_step),
    _refit=compiled(hard_iron._refit, _solve_symmetric=compiled(hard_iron._solve_symmetric),
                     smallest_eigenvalue=compiled(hard_iron.smallest_eigenvalue))))
first_trust = compiled(heading.first_state, new_state=new_trust)
reading_steps = compiled(lowpass.reading_steps)

#: Entries of :attr:`ImuState.counts`: steps since the last accelerometer and
#: magnetometer readings, magnetometer readings so far, and each one's last
#: interval (:func:`estimators.imu.lowpass.reading_steps`).
SINCE_ACC, SINCE_MAG, FIELDS, ACC_STEPS, MAG_STEPS = 0, 1, 2, 3, 4
#: Rows of ``imu_table``: the low-pass filters of the rest detector, of
#: gravity and of the field's steadiness, and their time constants.
REST_FILTER, GRAVITY_FILTER, STEADY_FILTER = 0, 1, 2
TIME_CONSTANTS = (rest.FILTER_TIME_CONSTANT_S, gravity.LOWPASS_TIME_CONSTANT_S,
                  heading.STEADY_TIME_CONSTANT_S)
#: Rows of a run's ``imu_work``, the models' working vectors (each reading
#: wrote into new arrays: 23 ns an array, a dozen a sample).
UP, GRAVITY_SCRATCH, FIELD, FIELD_E, STEADY_SCRATCH, TURN = 0, 1, 3, 4, 5, 7


def coefficient_table(dt: float) -> np.ndarray:
    """``(3, 5)``: each filter's coefficients (:data:`REST_FILTER`, …) at
    readings ``dt`` apart, the interval of nearly every reading: computed
    once, where :func:`coefficients` at each reading cost a tangent and a
    new array (36 ns, four times a sample)."""
    return np.array([lowpass.coefficients(tau, dt) for tau in TIME_CONSTANTS])


@njit(cache=True, inline="always", error_model="numpy")
def _coefficients(table, table_dt, row, interval):
    """:func:`coefficients` of filter ``row`` at ``interval``: the table's
    where the interval is its own (the same numbers), else computed."""
    if interval == table_dt:
        return table[row]
    return coefficients(TIME_CONSTANTS[row], interval)


def imu_state(estimators) -> dict:
    """Each run's IMU models (:class:`estimators.imu.ImuModels`) and the
    filter's settings of them, read off the per-run filters after their
    reset, as the ``imu_*`` fields of a kernel's state (flat: numba's
    parallel loops, which the kernels had, took no tuple nested in a tuple)."""
    first, count = estimators[0], len(estimators)
    models = [getattr(e, "imu", None) for e in estimators]
    work = {"imu_work": np.zeros((count, 8, 3)), "imu_drift": np.zeros((count, 3, 3)),
            "imu_nine": np.zeros((count, 9))}
    if models[0] is None:
        return {**work, "imu_table": np.zeros((3, 5)), "imu_table_dt": 0.0,
                "imu_on": False, "imu_lowpass": False, "imu_heading": False, "imu_rest": False,
                "imu_densities": np.zeros((count, 3)), "imu_strapdown": np.zeros((count, 4)),
                "imu_gravity": np.zeros((count, 4, 3)), "imu_detector": np.zeros((count, 9, 3)),
                "imu_trust": np.zeros((count, heading.STATE_SIZE)), "imu_rate_lp": np.zeros((count, 3)),
                "imu_counts": np.zeros((count, 5), dtype=np.int64),
                "imu_rotation": np.zeros((count, 5, 9)), "imu_field": np.zeros((count, 4, 3)),
                "imu_iron_fit": False, "imu_iron": np.zeros((count, hard_iron.STATE_SIZE))}
    return {**work, "imu_table": coefficient_table(models[0].dt), "imu_table_dt": models[0].dt,
            "imu_on": True, "imu_lowpass": first.gravity_model == "lowpass",
            "imu_heading": first.magnetometer_model == "heading",
            "imu_rest": bool(first.rest_updates),
            "imu_densities": np.array([[e.gravity_density, e.heading_density, e.rest_density]
                                       for e in estimators]),
            "imu_strapdown": np.array([m.strapdown for m in models]),
            "imu_gravity": np.array([m.gravity_filter for m in models]),
            "imu_detector": np.array([m.rest for m in models]),
            "imu_trust": np.array([m.trust for m in models]),
            "imu_rate_lp": np.array([m.rate_lp for m in models]),
            "imu_counts": np.array([[m.since_acc, m.since_mag, m.fields, m.acc_steps,
                                     m.mag_steps] for m in models], dtype=np.int64),
            "imu_rotation": np.array([np.vstack([m.rotation_integral[None], m.rotation_filter])
                                      for m in models]),
            "imu_field": np.array([m.field_filter for m in models]),
            "imu_iron_fit": bool(first.hard_iron_fit),
            "imu_iron": np.array([m.iron for m in models])}


#: The ``imu_*`` fields of a kernel's state, in order (see :func:`imu_state`).
IMU_FIELDS = ("imu_on", "imu_lowpass", "imu_heading", "imu_rest", "imu_densities",
              "imu_strapdown", "imu_gravity", "imu_detector", "imu_trust", "imu_rate_lp",
              "imu_counts", "imu_rotation", "imu_field", "imu_iron_fit", "imu_iron",
              "imu_table", "imu_table_dt", "imu_work", "imu_drift", "imu_nine")


@njit(cache=True, error_model="numpy")
def gyro_reading(counts, detector, rate_lp, run, rate, dt, table, table_dt):
    """:meth:`estimators.imu.ImuModels.gyro_reading`."""
    counts[run, SINCE_ACC] += 1
    counts[run, SINCE_MAG] += 1
    rest_gyro_step(rate, _coefficients(table, table_dt, REST_FILTER, dt), dt, detector[run],
                   rate_lp[run])


#: The models' arrays an accelerometer reading reads (:func:`gravity_models`),
#: and a magnetometer reading (:func:`field_models`): their places in the tuple.
(G_COUNTS, G_DETECTOR, G_STRAPDOWN, G_GRAVITY, G_ROTATION, G_WORK, G_DRIFT, G_NINE, G_TABLE,
 G_TABLE_DT, G_RATE_LP, G_DENSITIES) = range(12)
(F_COUNTS, F_IRON, F_IRON_FIT, F_WORK, F_TRUST, F_RATE_LP, F_STRAPDOWN, F_FIELD, F_TABLE,
 F_TABLE_DT, F_DENSITIES) = range(11)


@njit(cache=True, error_model="numpy")
def gravity_models(state) -> tuple:
    """The ``imu_*`` arrays of a kernel's ``state`` that an accelerometer
    reading reads, as a plain tuple (``G_*`` their places). Handed to a
    called function in place of the whole state: it counts a reference of
    every array it takes (the kernels package's docstring), and a state
    holds some forty. Not a named tuple: the parallel loop the kernels had
    could not take one made in the kernel."""
    return (state.imu_counts, state.imu_detector, state.imu_strapdown, state.imu_gravity,
            state.imu_rotation, state.imu_work, state.imu_drift, state.imu_nine, state.imu_table,
            state.imu_table_dt, state.imu_rate_lp, state.imu_densities)


@njit(cache=True, error_model="numpy")
def field_models(state) -> tuple:
    """The ``imu_*`` arrays that a magnetometer reading reads, as
    :func:`gravity_models` (``F_*`` their places)."""
    return (state.imu_counts, state.imu_iron, state.imu_iron_fit, state.imu_work,
            state.imu_trust, state.imu_rate_lp, state.imu_strapdown, state.imu_field,
            state.imu_table, state.imu_table_dt, state.imu_densities)


@njit(cache=True, inline="always", error_model="numpy")
def accelerometer_reading(models, run, specific_force, dt):
    """:meth:`estimators.imu.ImuModels.gravity_reading` on the arrays
    :func:`gravity_models` gives: ``(up, drift, interval, at_rest)`` —
    gravity's direction, the bias columns of its H, the interval and whether
    the body is at rest."""
    counts, detector, strapdown = models[G_COUNTS], models[G_DETECTOR], models[G_STRAPDOWN]
    gravity_state, rotation = models[G_GRAVITY], models[G_ROTATION]
    work, drift = models[G_WORK][run], models[G_DRIFT][run]
    up, scratch = work[UP], work[GRAVITY_SCRATCH:GRAVITY_SCRATCH + 2]
    steps, counts[run, ACC_STEPS] = reading_steps(counts[run, SINCE_ACC], counts[run, ACC_STEPS])
    interval = steps * dt
    counts[run, SINCE_ACC] = 0
    table, table_dt = models[G_TABLE], models[G_TABLE_DT]
    at_rest = rest_acc_step(specific_force,
                            _coefficients(table, table_dt, REST_FILTER, interval), interval,
                            detector[run], scratch[0])
    coeffs = _coefficients(table, table_dt, GRAVITY_FILTER, interval)
    gravity_direction(strapdown[run], specific_force, coeffs, gravity.LOWPASS_TIME_CONSTANT_S,
                      interval, gravity_state[run], scratch, up)
    drift_jacobian(strapdown[run], scratch[1], rotation[run, 0], coeffs,
                   gravity.LOWPASS_TIME_CONSTANT_S, interval, rotation[run, 1:],
                   models[G_NINE][run], drift)
    return up, drift, interval, at_rest


@njit(cache=True, inline="always", error_model="numpy")
def gravity_variance(models, run, density, interval):
    """The variance of the run's reading :func:`accelerometer_reading` has just
    given (:func:`estimators.imu.gravity.reading_variance`)."""
    return _reading_variance(density, interval, models[G_GRAVITY][run],
                             gravity.LOWPASS_TIME_CONSTANT_S)


@njit(cache=True, inline="always", error_model="numpy")
def calibrated_field(models, run, field, dt):
    """:meth:`estimators.imu.ImuModels.calibrated_field` on the arrays
    :func:`field_models` gives, into the run's working vector :data:`FIELD`."""
    out = models[F_WORK][run, FIELD]
    if models[F_IRON_FIT]:
        hard_iron_step(field, reading_steps(models[F_COUNTS][run, SINCE_MAG],
                                            models[F_COUNTS][run, MAG_STEPS])[0] * dt,
                       models[F_IRON][run], out)
    else:
        for i in range(3):
            out[i] = field[i]
    return out


@njit(cache=True, inline="always", error_model="numpy")
def field_reading(models, run, q, field, reference, known, dt):
    """:meth:`estimators.imu.ImuModels.field_reading` on the arrays
    :func:`field_models` gives: ψ, the interval, the trust, whether the field
    is validated and whether to forget the heading."""
    counts, trust, rate_lp = models[F_COUNTS], models[F_TRUST], models[F_RATE_LP]
    strapdown, field_state, work = models[F_STRAPDOWN], models[F_FIELD], models[F_WORK][run]
    scratch = work[FIELD_E]
    steps, counts[run, MAG_STEPS] = reading_steps(counts[run, SINCE_MAG], counts[run, MAG_STEPS])
    interval = steps * dt
    counts[run, SINCE_MAG] = 0
    if known and counts[run, FIELDS] == 0:
        norm = math.sqrt(reference[0] ** 2 + reference[1] ** 2 + reference[2] ** 2)
        fresh = new_trust(norm, -math.asin(reference[2] / norm))
        for i in range(heading.STATE_SIZE):
            trust[run, i] = fresh[i]
    norm, dip = field_in_reference(q, field, scratch)
    if not known and counts[run, FIELDS] == 0:
        fresh = first_trust(norm, dip)
        for i in range(heading.STATE_SIZE):
            trust[run, i] = fresh[i]
    counts[run, FIELDS] += 1
    steady = steady_step(strapdown[run], field,
                         _coefficients(models[F_TABLE], models[F_TABLE_DT], STEADY_FILTER,
                                       interval), interval, field_state[run],
                         work[STEADY_SCRATCH:STEADY_SCRATCH + 2])
    rate = rate_lp[run]
    trusted = trust_step(norm, dip, math.sqrt(rate[0] ** 2 + rate[1] ** 2 + rate[2] ** 2),
                         interval, trust[run], steady)
    psi = math.atan2(scratch[0], scratch[1]) - math.atan2(reference[0], reference[1])
    psi = (psi + math.pi) % (2.0 * math.pi) - math.pi
    return psi, interval, trusted, validated(trust[run]), _forget(trust[run])


@njit(cache=True, error_model="numpy")
def forget_heading(q, P):
    """``ErrorStateUpdates._forget_heading``: :func:`estimators.imu.heading.widen_heading`
    along the vertical in the body frame of ``q``."""
    _widen(to_body_frame(q, (0.0, 0.0, 1.0)), P)


@njit(cache=True, error_model="numpy")
def rest_update(q, beta, P, rate_lp, variance, scratch, dq):
    """The zero-rate update (:mod:`estimators.imu.rest`): ``y = ω̄ − β̂``,
    ``H = [0 I]``, ``R = variance I``, Joseph's form, then the reset.
    Returns the NIS and det S."""
    S, inverse, K, IK, T = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    for i in range(3):
        for j in range(3):
            S[i, j] = P[3 + i, 3 + j] + (variance if i == j else 0.0)
    _invert3(S, inverse)
    for i in range(6):
        for j in range(3):
            K[i, j] = P[i, 3] * inverse[0, j] + P[i, 4] * inverse[1, j] + P[i, 5] * inverse[2, j]
    y0, y1, y2 = rate_lp[0] - beta[0], rate_lp[1] - beta[1], rate_lp[2] - beta[2]
    nis = (y0 * (inverse[0, 0] * y0 + inverse[0, 1] * y1 + inverse[0, 2] * y2)
           + y1 * (inverse[1, 0] * y0 + inverse[1, 1] * y1 + inverse[1, 2] * y2)
           + y2 * (inverse[2, 0] * y0 + inverse[2, 1] * y1 + inverse[2, 2] * y2))
    determinant = (S[0, 0] * (S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1])
                   - S[0, 1] * (S[1, 0] * S[2, 2] - S[1, 2] * S[2, 0])
                   + S[0, 2] * (S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]))
    dx = scratch[5, 0]
    for i in range(6):
        dx[i] = K[i, 0] * y0 + K[i, 1] * y1 + K[i, 2] * y2
    for i in range(6):
        for j in range(6):
            IK[i, j] = (1.0 if i == j else 0.0) - (K[i, j - 3] if j >= 3 else 0.0)
    KRK = S                                        # S is spent: its slot holds K R Kᵀ
    for i in range(6):
        for j in range(6):
            KRK[i, j] = variance * (K[i, 0] * K[j, 0] + K[i, 1] * K[j, 1] + K[i, 2] * K[j, 2])
    joseph_covariance(P, IK, KRK, T)
    _apply(q, beta, dx, dq)
    return nis, determinant


@njit(cache=True, error_model="numpy")
def heading_update(q, beta, P, psi, variance, bias, gating, threshold, scratch, dq):
    """The heading-only update (:mod:`estimators.imu.heading`): ``y = ψ``,
    ``H = [vᵀ 0]``, the attitude gain projected on ``v``, the bias rows
    zeroed unless ``bias``; Joseph's form, then the reset; not applied if
    gating rejects it. Returns the NIS, whether it was applied and det S
    (as :func:`~benchmarks.engine.kernels.mekf_steps.joseph_update`)."""
    v = to_body_frame(q, (0.0, 0.0, 1.0))
    IK, T = scratch[3], scratch[4]
    K = scratch[2, 0]
    s = variance
    for i in range(3):
        for j in range(3):
            s += v[i] * P[i, j] * v[j]
    nis = psi * psi / s
    if gating and not nis <= threshold:
        return nis, False, s
    for i in range(6):
        K[i] = (P[i, 0] * v[0] + P[i, 1] * v[1] + P[i, 2] * v[2]) / s
    along = v[0] * K[0] + v[1] * K[1] + v[2] * K[2]
    for i in range(3):
        K[i] = v[i] * along
        if not bias:
            K[3 + i] = 0.0
    for i in range(6):
        for j in range(6):
            IK[i, j] = (1.0 if i == j else 0.0) - (K[i] * v[j] if j < 3 else 0.0)
    for i in range(6):
        for j in range(6):
            scratch[1, i, j] = K[i] * K[j] * variance
    # H is zero in the bias columns: I − KH's are the identity's, their products skipped.
    joseph_covariance(P, IK, scratch[1], T, 6, True)
    dx = scratch[5, 0]
    for i in range(6):
        dx[i] = K[i] * psi
    _apply(q, beta, dx, dq)
    return nis, True, s


@njit(cache=True, error_model="numpy")
def _apply(q, beta, dx, dq):
    """The reset: ``q ← q ⊗ δq(δθ)``, ``β ← β + δβ``."""
    quat_exp(dx[0], dx[1], dx[2], dq)
    quat_times_normalized(q, dq, q)
    for i in range(3):
        beta[i] += dx[3 + i]


@njit(cache=True, error_model="numpy")
def _invert3(S, inverse):
    """The inverse of a symmetric positive definite 3x3 ``S`` (its adjugate over
    its determinant)."""
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 1], S[1, 2], S[2, 2]
    A, B, C = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * A + b * B + c * C
    inverse[0, 0], inverse[0, 1], inverse[0, 2] = A / det, B / det, C / det
    inverse[1, 0], inverse[1, 1], inverse[1, 2] = B / det, (a * f - c * c) / det, \
        (b * c - a * e) / det
    inverse[2, 0], inverse[2, 1], inverse[2, 2] = C / det, (b * c - a * e) / det, \
        (a * d - b * b) / det
