"""The sensors' draws, shared by every estimator kernel: each step's gyro
reading and, when one is due, the star tracker's, made from the same standard
normals the per-run path draws (:class:`sensors.Gyro` with its bias random
walk, its Gauss–Markov part, scale and misalignment;
:class:`sensors.StarTracker` and :class:`sensors.RotationStarTracker` with
dropouts, outages and sign).

Every kernel makes the readings itself, inside its own loop, from the block's
normals: the arithmetic is a few operations a step, and reading the normals
while the filter computes costs less than a separate pass that would write
the readings out and read them back (measured: a shared pass, even over
stretches short enough to stay in the cache, made the workshop's three
estimators 25 % slower). The readings are the same numbers in every kernel; each
advances its own copy of the gyro's true bias.

Their arguments are plain arrays, not the block's named tuple: numba
dropped writes into a named tuple's arrays made inside the parallel loop
the kernels had, and every read of a field in a loop costs a reference
count (measured: the loop took three times as long). The star tracker's
arrays go as one plain tuple (:func:`star_arrays`): read at its readings
only, they cost nothing measurable so; the gyro's, read every step, go one
by one.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels.algebra import quat_exp, quat_times_normalized


class SensorState(NamedTuple):
    """What the sensors carry from step to step, one row per run: the gyro's
    true bias (each kernel advances its own copy, the same numbers)."""

    bias: np.ndarray             # (B, 6) β_k: its walk part (with β_0), its Gauss–Markov part
    bias_last: np.ndarray        # (B, 3) β at the run's last step


#: ``bias_model``'s entries (an array, so that the kernels pass it on as one value).
WALK_STD, MARKOV_PHI, MARKOV_STD, HAS_WALK, HAS_MARKOV = range(5)


def bias_model(gyro) -> np.ndarray:
    """The gyro's bias model as the kernels read it: the walk's step σ, the
    Gauss–Markov part's φ and step σ, and whether each is there."""
    return np.array([gyro.bias_step_std, gyro.markov_phi, gyro.markov_step_std,
                     float(gyro.bias_random_walk > 0), float(gyro.bias_instability_radps > 0)])


@njit(cache=True, error_model="numpy")
def _flight_gyro(w, omega, std, normals, scale_matrix, has_scale, has_bias, model,
                 bias, bias_last, last):
    """w = ω (+ K ω) (+ ½(β_k + β_{k+1})) + σ N_v, advancing the true bias β:
    its random walk and its Gauss–Markov part, b ← φ b + σ_b √(1 − φ²) N_b
    (sensors.gyro; the normals are [N_v, N_u if a walk, N_b if a Gauss–Markov part])."""
    for i in range(3):
        w[i] = omega[i]
    if has_scale:
        for i in range(3):
            w[i] = w[i] + (omega[0] * scale_matrix[i, 0] + omega[1] * scale_matrix[i, 1]
                           + omega[2] * scale_matrix[i, 2])
    if has_bias:
        # Without a walk the walk's part stays; reading its normals there
        # would run past the row (and the buffer's end).
        walk, markov = model[HAS_WALK] > 0.0, model[HAS_MARKOV] > 0.0
        markov_column = 6 if walk else 3
        for i in range(3):
            now = bias[i] + bias[3 + i]
            if last:
                bias_last[i] = now
            following = bias[i] + model[WALK_STD] * normals[3 + i] if walk else bias[i]
            markov_next = (model[MARKOV_PHI] * bias[3 + i]
                           + model[MARKOV_STD] * normals[markov_column + i]
                           if markov else bias[3 + i])
            w[i] = w[i] + 0.5 * (now + (following + markov_next))
            bias[i] = following
            bias[3 + i] = markov_next
    for i in range(3):
        w[i] = w[i] + std * normals[i]



@njit(cache=True, inline="always", error_model="numpy")
def gyro_arrays(block, sensors):
    """What :func:`gyro_reading` reads, taken out of the block's tuples (before
    a kernel's loop over its runs: see the module's docstring)."""
    return (block.omega_true, block.gyro_std, block.gyro_normals, block.gyro_scale,
            block.has_scale, block.has_bias, block.bias_model, sensors.bias,
            sensors.bias_last)


#: Where the steps between a run's readings are in :func:`star_arrays`' tuple.
STEPS_BETWEEN = 2


@njit(cache=True, inline="always", error_model="numpy")
def star_arrays(block):
    """What :func:`star_reading` reads, likewise."""
    return (block.rotation_model, block.star_std, block.steps_between, block.star_normals,
            block.sigma_rad, block.sensor_to_body, block.canonical, block.outage,
            block.dropout_probability, block.dropout_uniforms)


@njit(cache=True, inline="always", error_model="numpy")
def first_countdown(k0, star, run):
    """Steps from step ``k0`` to run ``run``'s next star tracker reading
    (``star``: :func:`star_arrays`; readings at k ≡ 0 mod its steps between
    readings): a countdown, instead of a modulo every step."""
    m = star[STEPS_BETWEEN][run]
    return (m - k0 % m) % m


@njit(cache=True, inline="always", error_model="numpy")
def gyro_reading(w, run, t, k, last_step, omega, std, normals, scale, has_scale, has_bias,
                 bias_model, bias, bias_last):
    """The gyro's reading at step ``k`` (index ``t`` of its block) into ``w``:
    ω (+ K ω) (+ ½(β_k + β_{k+1})) + σ N_v, advancing the true bias. Its
    arrays come one by one (:func:`gyro_arrays`), not as their tuple: read
    every step, a tuple's items cost a reference count each (the EKF's batch
    5 % slower, measured)."""
    if not (has_scale or has_bias):
        for i in range(3):
            w[i] = omega[t, i] + std[run] * normals[run, t, i]
    else:
        _flight_gyro(w, omega[t], std[run], normals[run, t], scale, has_scale, has_bias,
                     bias_model, bias[run], bias_last[run], k == last_step)


@njit(cache=True, inline="always", error_model="numpy")
def star_step(z, dq, run, j, countdown, reading, q_true, star):
    """The tracker at the block's step ``j`` (``star``: :func:`star_arrays`):
    whether a reading is available (made into ``z`` if one is due), the next
    countdown and the index of the next reading's normals."""
    if countdown > 0:
        return False, countdown - 1, reading
    (rotation_model, std, steps_between, normals, sigma, mount, canonical, outage,
     dropout_probability, uniforms) = star
    available = star_reading(z, dq, run, j, reading, q_true, rotation_model, std, normals,
                             sigma, mount, canonical, outage, dropout_probability, uniforms)
    return available, steps_between[run] - 1, reading + 1


@njit(cache=True, error_model="numpy")
def star_reading(z, dq, run, t, r, q_true, rotation_model, std, normals, sigma, mount,
                 canonical, outage, dropout_probability, uniforms):
    """The tracker's reading ``r`` of the block, at its index ``t``, into ``z``;
    returns whether it is available (outages and dropouts; ``model =
    "none"`` is an outage throughout, with no normals drawn)."""
    if outage[t]:
        return False
    if rotation_model:
        t0 = sigma[0] * normals[run, r, 0]
        t1 = sigma[1] * normals[run, r, 1]
        t2 = sigma[2] * normals[run, r, 2]
        quat_exp(mount[0, 0] * t0 + mount[0, 1] * t1 + mount[0, 2] * t2,
                 mount[1, 0] * t0 + mount[1, 1] * t1 + mount[1, 2] * t2,
                 mount[2, 0] * t0 + mount[2, 1] * t1 + mount[2, 2] * t2, dq)
        quat_times_normalized(q_true[t], dq, z)
        if canonical and z[0] < 0:
            for i in range(4):
                z[i] = -z[i]
        return not (dropout_probability > 0.0 and uniforms[run, r] < dropout_probability)
    for i in range(4):
        z[i] = q_true[t, i] + std[run] * normals[run, r, i]
    norm = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2] + z[3] * z[3])
    for i in range(4):
        z[i] = z[i] / norm
    return True


@njit(cache=True, inline="always", error_model="numpy")
def vector_arrays(block):
    """The vector sensors' readings of the block (see :class:`Block`), taken
    out of its tuple like :func:`star_arrays`."""
    return (block.vector_body, block.vector_reference, block.vector_variance,
            block.vector_available, block.vector_dof, block.vector_magnetic,
            block.vector_gravity, block.vector_known)
