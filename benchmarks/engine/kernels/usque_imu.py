"""USQUE's IMU models in the engine (:class:`estimators.usque.USQUE` with
``gravity_model``, ``magnetometer_model`` or ``rest_updates``): the models'
state machines are the MEKF's (:mod:`benchmarks.engine.kernels.imu`, the
per-run modules' own functions compiled); the updates are made on the sigma
points as the per-run class makes them:

* gravity's low-passed direction: ``h(χ) = A(q̂ ⊗ δq(δp))ᵀ e_z + D (β − β̄)``;
* the zero-rate update at rest: ``h(χ) = β``, never gated;
* the heading: each point's heading error, measured as zero, the gain's
  attitude rows projected on the vertical and its bias rows zeroed unless
  the field is validated, the covariance in the general gain's form.

Each update is followed by the reset (``q̂ ← q̂ ⊗ δq(δp)``), and the next
update of the step draws its sigma points anew, as
``USQUE._fresh_sigma_points`` does.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.engine.kernels import imu
from benchmarks.engine.kernels.algebra import to_body_frame
from benchmarks.engine.kernels.common import fold_innovation
from benchmarks.engine.kernels.unscented import (N_SIGMAS, fold_reference, output, product,
                                                 quat_from_grp, sigma_points, unit,
                                                 unscented_update)
from estimators.usque import STATE_SIZE


@njit(cache=True, error_model="numpy")
def propagate_strapdown(strapdown, rotation, rate, x, dt, turn):
    """The IMU models' strapdown by the mean's bias-corrected rotation
    (``USQUE.propagate``), before the sigma points move; ``turn`` (3,) scratch."""
    for i in range(3):
        turn[i] = (rate[i] - x[3 + i]) * dt
    imu.strapdown_step(strapdown, turn, strapdown)
    imu.integrate_rotation(strapdown, dt, rotation)


@njit(cache=True, error_model="numpy")
def _sigma_attitude(q, sigma):
    g0, g1, g2, g3 = quat_from_grp(sigma[0], sigma[1], sigma[2])
    return unit(product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))


@njit(cache=True, error_model="numpy")
def _heading(a, field, turned):
    """``estimators.usque._heading``: the field's heading through ``a``."""
    imu._rotate(a, field, turned)
    return math.atan2(turned[0], turned[1])


@njit(cache=True, error_model="numpy")
def gravity_update(q, x, P, sigmas, up, variance, drift, Wm, Wc, gating, threshold, scratch,
                   predicted, R):
    """``USQUE._gravity_update`` (the update only: the caller resets)."""
    for i in range(N_SIGMAS):
        a = np.array(_sigma_attitude(q, sigmas[i]))
        p0, p1, p2 = to_body_frame(a, (0.0, 0.0, 1.0))
        d0, d1, d2 = sigmas[i, 3] - x[3], sigmas[i, 4] - x[4], sigmas[i, 5] - x[5]
        predicted[i, 0] = p0 + (drift[0, 0] * d0 + drift[0, 1] * d1 + drift[0, 2] * d2)
        predicted[i, 1] = p1 + (drift[1, 0] * d0 + drift[1, 1] * d1 + drift[1, 2] * d2)
        predicted[i, 2] = p2 + (drift[2, 0] * d0 + drift[2, 1] * d1 + drift[2, 2] * d2)
    _diagonal(R, variance)
    return unscented_update(x, P, sigmas, predicted, up[0], up[1], up[2], R, Wm, Wc, gating,
                            threshold, scratch)


@njit(cache=True, error_model="numpy")
def rest_update(x, P, sigmas, rate, variance, Wm, Wc, scratch, predicted, R):
    """``USQUE._rest_update``: ``h(χ) = β``, never gated."""
    for i in range(N_SIGMAS):
        predicted[i, 0], predicted[i, 1], predicted[i, 2] = sigmas[i, 3], sigmas[i, 4], \
            sigmas[i, 5]
    _diagonal(R, variance)
    return unscented_update(x, P, sigmas, predicted, rate[0], rate[1], rate[2], R, Wm, Wc,
                            False, 0.0, scratch)


@njit(cache=True, error_model="numpy")
def _diagonal(R, variance):
    for a in range(3):
        for b in range(3):
            R[a, b] = variance if a == b else 0.0


@njit(cache=True, error_model="numpy")
def heading_update(q, x, P, sigmas, field, psi, variance, validated, Wm, Wc, gating,
                   threshold):
    """``USQUE._heading_update``: returns the NIS, whether it was applied
    and S."""
    estimate, turned, h = np.empty(4), np.empty(3), np.empty(N_SIGMAS)
    output(q, x, estimate)
    mean_heading = _heading(estimate, field, turned)
    zp = 0.0
    for i in range(N_SIGMAS):
        a = np.array(_sigma_attitude(q, sigmas[i]))
        turn = _heading(a, field, turned) - mean_heading
        h[i] = psi + ((turn + math.pi) % (2.0 * math.pi) - math.pi)
        zp += Wm[i] * h[i]
    S = variance
    for i in range(N_SIGMAS):
        S += Wc[i] * (h[i] - zp) * (h[i] - zp)
    y = -zp
    nis = y * y / S
    if gating and not nis <= threshold:
        return nis, False, S
    Pxz, K = np.empty(STATE_SIZE), np.empty(STATE_SIZE)
    for a in range(STATE_SIZE):
        total = 0.0
        for i in range(N_SIGMAS):
            total += Wc[i] * (sigmas[i, a] - x[a]) * (h[i] - zp)
        Pxz[a] = total
        K[a] = total / S
    v = to_body_frame(estimate, (0.0, 0.0, 1.0))
    along = v[0] * K[0] + v[1] * K[1] + v[2] * K[2]
    for a in range(3):
        K[a] = v[a] * along
        if not validated:
            K[3 + a] = 0.0
    for a in range(STATE_SIZE):
        x[a] += K[a] * y
    for a in range(STATE_SIZE):
        for b in range(STATE_SIZE):
            P[a, b] = P[a, b] - K[a] * Pxz[b] - Pxz[a] * K[b] + K[a] * (S * K[b])
    return nis, True, S


@njit(cache=True, error_model="numpy")
def reading(q, x, P, sigmas, run, j, s, dt, body, reference, gravity, magnetic, known, dof,
            gating, gate, rejected, streaming, likelihood, state, spread, Wm, Wc, updated,
            scratch, predicted, R):
    """A vector reading through the IMU models where the settings ask
    (``USQUE.correct_vector``): ``(taken, factored, updated)`` — whether the
    models took it, whether every Cholesky factor existed, and whether the
    sigma points are stale (an update was made); ``gating`` and ``gate`` are
    the run's."""
    densities = state.imu_densities[run]
    if gravity[s]:
        force = body[run, j, s]
        models = imu.gravity_models(state)
        up, drift, interval, at_rest = imu.accelerometer_reading(models, run, force, dt)
        last_nis, last_det, kept = 0.0, 1.0, True
        if state.imu_lowpass:
            if updated and not sigma_points(x, P, spread, sigmas, scratch[0]):
                return True, False, updated
            variance = imu.gravity_variance(models, run, densities[0], interval)
            last_nis, kept, last_det = gravity_update(
                q, x, P, sigmas, up, variance, drift, Wm, Wc, gating, gate[dof[s]], scratch,
                predicted, R)
            if not kept:
                rejected[run, s] += 1
                if streaming:              # at the gate (InnovationGate.accepts)
                    fold_innovation(run, gate[dof[s]], last_det, likelihood)
            fold_reference(q, x)
            updated = True
        if state.imu_rest and at_rest:
            if updated and not sigma_points(x, P, spread, sigmas, scratch[0]):
                return True, False, updated
            last_nis, _, last_det = rest_update(x, P, sigmas, state.imu_rate_lp[run],
                                                densities[2] / interval, Wm, Wc, scratch,
                                                predicted, R)
            fold_reference(q, x)
            updated = True
        if streaming and kept and state.imu_lowpass:
            fold_innovation(run, last_nis, last_det, likelihood)
        return state.imu_lowpass, True, updated
    if not (magnetic[s] and state.imu_heading):
        return False, True, updated
    factored, updated = _field_reading(q, x, P, sigmas, run, body[run, j, s], reference[j, s],
                                       known[s], dt, gating, gate[1], rejected[run], s,
                                       streaming, likelihood, state, spread, Wm, Wc, updated,
                                       scratch)
    return True, factored, updated


@njit(cache=True, error_model="numpy")
def _field_reading(q, x, P, sigmas, run, field, reference, known, dt, gating, gate, rejected,
                   s, streaming, likelihood, state, spread, Wm, Wc, updated, scratch):
    """A magnetometer reading through the heading model (``ImuUpdates._heading``):
    ``(factored, updated)`` as :func:`reading` returns them."""
    estimate = np.empty(4)
    output(q, x, estimate)
    models = imu.field_models(state)
    field = imu.calibrated_field(models, run, field, dt)
    psi, interval, trust, validated, forget = imu.field_reading(models, run, estimate, field,
                                                                reference, known, dt)
    if forget:
        imu.forget_heading(estimate, P)
        updated = True
    if trust == 0.0:                   # an untrusted field: no update, the reset all the same
        rejected[s] += 1
        if x[0] != 0.0 or x[1] != 0.0 or x[2] != 0.0:
            fold_reference(q, x)
        return True, True
    if updated and not sigma_points(x, P, spread, sigmas, scratch[0]):
        return False, updated
    nis, used, S = heading_update(q, x, P, sigmas, field, psi,
                                  trust * trust * state.imu_densities[run, 1] / interval,
                                  validated, Wm, Wc, gating, gate)
    if streaming:
        fold_innovation(run, nis if used else gate, S, likelihood)
    if not used:
        rejected[s] += 1
    fold_reference(q, x)
    return True, True
