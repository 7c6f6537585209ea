r"""Torque-free rigid body: the truth the sensors observe.

Euler's equations with no external torque, in the body frame,

.. math:: I \dot\omega = -\omega \times (I \omega), \qquad
          \dot q = \tfrac12\, q \otimes [0, \omega],

are integrated with scipy's 8th-order Dormand–Prince method (``DOP853``) at
tight tolerances. The workshop's Simulink model used a loose variable-step
solver; we are deliberately far more accurate, so that the truth is never the
limiting error: kinetic energy and ``|angular momentum|`` are conserved to
better than 1e-9 relative, and ``|q| = 1`` to 1e-12 (each output quaternion is
renormalised, which removes the integrator's norm drift without touching the
attitude it represents).

A torque-free body also has a closed-form solution for ``ω`` in Jacobi
elliptic functions (:func:`closed_form_body_rates`; Landau & Lifshitz,
*Mechanics*, §37), which the tests use to check the integrator exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import DOP853, solve_ivp
from scipy.special import ellipj, ellipkinc

from dynamics.validation import InvalidParameterError

# Integrator tolerances: relative 1e-12 keeps the invariants at the 1e-11
# level over 50 s of the default tumble; absolute 1e-15 is far below both the
# rates (~0.07 rad/s) and the quaternion components (~1).
_RTOL = 1e-12
_ATOL = 1e-15


@dataclass(frozen=True)
class RigidBodyTruth:
    """True motion sampled on the time grid.

    Attributes
    ----------
    time_s : (N,) array, seconds
    q_true : (N, 4) array, scalar-first unit quaternions (body → reference)
    omega_true_radps : (N, 3) array, body rates in rad/s, body frame
    """

    time_s: np.ndarray
    q_true: np.ndarray
    omega_true_radps: np.ndarray


def kinetic_energy(inertia_kg_m2: np.ndarray, omega_radps: np.ndarray) -> np.ndarray:
    """Rotational kinetic energy ``½ ωᵀ I ω`` in joules, for ``(..., 3)`` rates."""
    omega = np.asarray(omega_radps, dtype=float)
    return 0.5 * np.einsum("...i,ij,...j->...", omega, inertia_kg_m2, omega)


def angular_momentum_body(inertia_kg_m2: np.ndarray, omega_radps: np.ndarray) -> np.ndarray:
    """Angular momentum ``I ω`` in the body frame, kg m²/s, for ``(..., 3)`` rates."""
    return np.asarray(omega_radps, dtype=float) @ np.asarray(inertia_kg_m2).T


def _equations_of_motion(inertia_kg_m2: np.ndarray):
    inertia_inv = np.linalg.inv(inertia_kg_m2)

    def rhs(_t, state):
        w, x, y, z, p, q, r = state
        omega = state[4:]
        omega_dot = inertia_inv @ -np.cross(omega, inertia_kg_m2 @ omega)
        # q_dot = 0.5 * Ξ(q) ω, written out (this runs thousands of times).
        q_dot = 0.5 * np.array([
            -x * p - y * q - z * r,
            w * p - z * q + y * r,
            z * p + w * q - x * r,
            -y * p + x * q + w * r,
        ])
        return np.concatenate([q_dot, omega_dot])

    return rhs


def simulate_torque_free(inertia_kg_m2: np.ndarray, q0: np.ndarray,
                         omega0_radps: np.ndarray, time_s: np.ndarray) -> RigidBodyTruth:
    """Integrate the torque-free body and sample it at ``time_s``.

    Parameters
    ----------
    inertia_kg_m2 : (3, 3) array
        Inertia tensor in the body frame, kg m².
    q0 : (4,) array
        Initial attitude, scalar-first (normalised here).
    omega0_radps : (3,) array
        Initial body rate, rad/s.
    time_s : (N,) array
        Increasing sample times, seconds, starting at 0.
    """
    inertia = np.asarray(inertia_kg_m2, dtype=float)
    time_s = np.asarray(time_s, dtype=float)
    state0 = _initial_state(q0, omega0_radps)
    if len(time_s) == 1:
        states = state0[:, None]
    else:
        solution = solve_ivp(_equations_of_motion(inertia), (time_s[0], time_s[-1]), state0,
                             method="DOP853", t_eval=time_s, rtol=_RTOL, atol=_ATOL)
        if not solution.success:  # pragma: no cover - DOP853 does not fail on this smooth system
            raise RuntimeError(f"truth integration failed: {solution.message}")
        states = solution.y
    return _truth(time_s, states)


def torque_free_blocks(inertia_kg_m2: np.ndarray, q0: np.ndarray, omega0_radps: np.ndarray,
                       dt: float, n_steps: int, block_steps: int):
    """The truth of :func:`simulate_torque_free` on the grid ``t_k = k dt``,
    ``k < n_steps``, yielded as consecutive :class:`RigidBodyTruth` blocks of
    ``block_steps`` steps (the last may be shorter), so that memory does not
    grow with the run's length.

    The numbers are :func:`simulate_torque_free`'s, bit for bit: this is
    ``solve_ivp``'s own loop (the DOP853 stepper, each step's dense output
    evaluated at the grid times it passes), with the grid times computed as
    they come instead of held in an array.
    """
    inertia = np.asarray(inertia_kg_m2, dtype=float)
    state0 = _initial_state(q0, omega0_radps)
    pending_time, pending_states = [np.zeros(1)], [state0[:, None]]
    held = 1
    if n_steps > 1:
        t_final = float((n_steps - 1) * dt)
        solver = DOP853(_equations_of_motion(inertia), 0.0, state0, t_final,
                        rtol=_RTOL, atol=_ATOL)
        next_k = 1
        while next_k < n_steps:
            solver.step()
            if solver.status == "failed":  # pragma: no cover - as in simulate_torque_free
                raise RuntimeError("truth integration failed")
            # The grid times in (t_old, t], as solve_ivp's searchsorted picks them.
            stop = next_k
            while stop < n_steps and stop * dt <= solver.t:
                stop += 1
            if stop > next_k:
                times = np.arange(next_k, stop) * dt
                pending_time.append(times)
                pending_states.append(solver.dense_output()(times))
                held += stop - next_k
                next_k = stop
            while held >= block_steps or (next_k == n_steps and held):
                times, states = np.concatenate(pending_time), np.hstack(pending_states)
                yield _truth(times[:block_steps], states[:, :block_steps])
                pending_time, pending_states = [times[block_steps:]], [states[:, block_steps:]]
                held = len(pending_time[0])
    else:
        yield _truth(pending_time[0], pending_states[0])


def _initial_state(q0, omega0_radps) -> np.ndarray:
    return np.concatenate([np.asarray(q0, float) / np.linalg.norm(q0),
                           np.asarray(omega0_radps, dtype=float)])


def _truth(time_s: np.ndarray, states: np.ndarray) -> RigidBodyTruth:
    q_true = states[:4].T
    q_true = q_true / np.linalg.norm(q_true, axis=1, keepdims=True)
    return RigidBodyTruth(time_s=time_s, q_true=q_true, omega_true_radps=states[4:].T.copy())


def _elliptic_amplitudes(moments: np.ndarray, omega0: np.ndarray) -> tuple:
    """``(d, s, c, amp)``: the tumble axis ``d``, the middle axis ``s``, the
    other extreme ``c``, and each axis's amplitude (``amp[d]`` signed as the
    initial rate about it), from energy and angular momentum
    (:func:`closed_form_body_rates`)."""
    two_e = float(np.sum(moments * omega0**2))
    m_sq = float(np.sum((moments * omega0) ** 2))
    order = np.argsort(moments)
    mid = order[1]
    # Tumble ("d") axis and the other extreme ("c") axis.
    d, c = (order[0], order[2]) if m_sq < two_e * moments[mid] else (order[2], order[0])
    s = mid
    amp = {}
    amp[d] = np.sqrt((two_e * moments[c] - m_sq) / (moments[d] * (moments[c] - moments[d])))
    amp[s] = np.sqrt((two_e * moments[d] - m_sq) / (moments[s] * (moments[d] - moments[s])))
    amp[c] = np.sqrt((two_e * moments[d] - m_sq) / (moments[c] * (moments[d] - moments[c])))
    if omega0[d] == 0:
        raise InvalidParameterError("omega0_radps", omega0,
                                    "needs a non-zero rate about the tumble axis")
    amp[d] = np.copysign(amp[d], omega0[d])
    return d, s, c, amp


def closed_form_body_rates(principal_moments_kg_m2, omega0_radps, time_s) -> np.ndarray:
    r"""Exact ``ω(t)`` of a torque-free body with a diagonal inertia tensor.

    In the generic case (distinct moments, not a separatrix motion) the body
    rates are Jacobi elliptic functions of a common argument
    :math:`u = \lambda t + u_0` (Landau & Lifshitz, *Mechanics*, §37):
    the axis the body tumbles about (smallest moment when
    :math:`M^2 < 2 E I_\text{mid}`, largest otherwise) follows ``a_d dn(u|m)``,
    the middle axis ``a_s sn(u|m)`` and the remaining one ``a_c cn(u|m)``.
    The amplitudes follow from energy ``E`` and ``M = |I ω|``; ``λ`` and the
    parameter ``m`` follow from substituting into Euler's equations, and
    ``u_0`` from the initial rates.

    Parameters
    ----------
    principal_moments_kg_m2 : (3,) array, distinct positive values
    omega0_radps : (3,) array, rad/s, with a non-zero component about the
        tumble axis
    time_s : (N,) array, seconds

    Returns
    -------
    (N, 3) array of body rates in rad/s.
    """
    moments = np.asarray(principal_moments_kg_m2, dtype=float)
    omega0 = np.asarray(omega0_radps, dtype=float)
    if len(set(moments.tolist())) != 3:
        raise InvalidParameterError("principal_moments_kg_m2", moments,
                                    "must be three distinct values for the elliptic solution")
    d, s, c, amp = _elliptic_amplitudes(moments, omega0)

    # ω̇_a = κ_a ω_b ω_c with (a, b, c) cyclic: Euler's equations, torque-free.
    def kappa(a):
        b, cc = (a + 1) % 3, (a + 2) % 3
        return (moments[b] - moments[cc]) / moments[a]

    def other_product(a):
        b, cc = (a + 1) % 3, (a + 2) % 3
        return amp[b] * amp[cc]

    # Substituting ω_s = a_s sn(u): a_s λ cn dn = κ_s a_d a_c cn dn.
    rate = kappa(s) * other_product(s) / amp[s]
    # ω_d = a_d dn(u): -a_d m λ sn cn = κ_d a_s a_c sn cn.
    parameter_m = -kappa(d) * other_product(d) / (amp[d] * rate)
    phase = np.arctan2(omega0[s] / amp[s], omega0[c] / amp[c])
    u0 = ellipkinc(phase, parameter_m)
    sn, cn, dn, _ = ellipj(rate * np.asarray(time_s, dtype=float) + u0, parameter_m)
    omega = np.empty((np.size(time_s), 3))
    omega[:, d] = amp[d] * dn
    omega[:, s] = amp[s] * sn
    omega[:, c] = amp[c] * cn
    return omega
