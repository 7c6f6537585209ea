r"""The best any filter could do: Riccati and posterior Cramér–Rao bounds.

The linearised problem is the MEKF's error model (:mod:`estimators.mekf`)
with the *truth's* noise: the body-frame attitude error :math:`\delta\theta`
(and, when the gyro has a bias model, the bias error :math:`\Delta\beta`)
evolves as :math:`x_{k+1} = \Phi_k x_k + w_k`, :math:`w_k \sim \mathcal N(0,
Q_k)` with :math:`\Phi_k, Q_k` the exact discrete model of §6.2.4 at the
*true* rate :math:`\omega_k` (the rate the gyro reads: sampled at the step's
start, or its average over the step, :mod:`sensors.gyro`) and the gyro's own
:math:`\sigma_v, \sigma_u` (a Gauss–Markov bias as its equivalent random
walk, exact over times short against its correlation time),
and each star tracker reading measures :math:`y = \delta\theta + v`,
:math:`v \sim \mathcal N(0, R)` with :math:`R` the tracker's body-frame
covariance (for the workshop tracker, :math:`(2\sigma)^2 I_3`). Each vector
reading (:mod:`sensors.vector`) measures :math:`y = [b\times]\delta\theta + v`,
:math:`v \sim \mathcal N(0, \sigma^2 I_3)`, with :math:`b = A(q)^\mathsf{T} r`
along the *true* attitude: it adds the information
:math:`H^\mathsf{T} R^{-1} H = \sigma^{-2}(|b|^2 I_3 - b b^\mathsf{T})` (none
along :math:`b`), at the steps it is read (the sun sensors' eclipses and
fields of view follow from the truth, so the bound knows them).

**Posterior Cramér–Rao bound along the true trajectory** (Tichavský,
Muravchik & Nehorai, *IEEE Trans. Signal Processing* 46(5), 1998): the
information recursion :math:`J_{k+1} = D^{22}_k - D^{21}_k (J_k +
D^{11}_k)^{-1} D^{12}_k` with, for additive Gaussian noise,
:math:`D^{11} = \Phi^\mathsf{T} Q^{-1}\Phi`, :math:`D^{12} = -\Phi^\mathsf{T}
Q^{-1}`, :math:`D^{22} = Q^{-1} + H^\mathsf{T}R^{-1}H`. By the matrix
inversion lemma this is the Riccati recursion of the Kalman filter, which we
run in covariance form (it also holds when :math:`Q` is singular, as with no
bias random walk):

.. math:: P^-_{k+1} = \Phi_k P^+_k \Phi_k^\mathsf{T} + Q_k, \qquad
          P^+_k = \bigl((P^-_k)^{-1} + H^\mathsf{T} R^{-1} H\bigr)^{-1}
          \ \text{at reading steps}, \qquad P_0 = \text{the prior}.

``P⁻`` bounds an estimate made before the step's reading (the workshop EKF's
``output="prior"``), ``P⁺`` one made after it.

**Periodic steady state** (:func:`periodic_steady_state`): with a star
tracker every :math:`m` steps, no bias random walk and a rotation per period
that is small (or isotropic noise, where rotations leave :math:`P`
unchanged), the recursion over one period is time invariant,
:math:`P^-_{+} = P^+ + m Q`, and its fixed point is the discrete algebraic
Riccati equation's solution (``scipy.linalg.solve_discrete_are``).

A covariance becomes an angle as the distribution of :math:`|\delta\theta|`:
its RMS is :math:`\sqrt{\operatorname{tr} P}`, its mean
:math:`E|\delta\theta|` (for isotropic :math:`P = s^2 I_3`, the Maxwell mean
:math:`2 s \sqrt{2/\pi}`) estimated here from a fixed set of standard normal
draws. A filter's **efficiency** is its RMS error over the bound's RMS (≥ 1
in expectation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from benchmarks.simulation import simulate_truth
from estimators.mekf import discrete_error_model
from dynamics.validation import InvalidParameterError

#: Standard normal draws for E|δθ| (fixed: the bound is a deterministic number).
_MEAN_DRAWS = np.random.default_rng(19980501).standard_normal((200_000, 3))


@dataclass(frozen=True)
class AttitudeBound:
    """The bound over a scenario's time grid.

    ``prior`` / ``posterior`` are the attitude block (3x3, rad²) at every step
    before and after that step's reading.
    """

    time_s: np.ndarray
    prior: np.ndarray
    posterior: np.ndarray

    def covariance(self, output: str = "posterior") -> np.ndarray:
        return self.prior if output == "prior" else self.posterior

    def rms_deg(self, output: str = "posterior", start: int = 0) -> float:
        """RMS of the attitude error angle over the steps from ``start``, degrees."""
        covariance = self.covariance(output)[start:]
        return float(np.degrees(np.sqrt(np.mean(np.trace(covariance, axis1=1, axis2=2)))))

    def mean_deg(self, output: str = "posterior", start: int = 0, samples: int = 200) -> float:
        """Mean of the error angle over the steps from ``start``, degrees (from
        ``samples`` steps evenly spread)."""
        covariance = self.covariance(output)[start:]
        picked = covariance[np.linspace(0, len(covariance) - 1, samples).astype(int)]
        return float(np.degrees(np.mean([mean_angle_rad(c) for c in picked])))

    def std_deg(self, output: str = "posterior", start: int = 0, samples: int = 200) -> float:
        """Standard deviation of the error angle pooled over the steps, degrees."""
        mean = self.mean_deg(output, start, samples)
        return float(np.sqrt(max(self.rms_deg(output, start) ** 2 - mean ** 2, 0.0)))


def mean_angle_rad(covariance: np.ndarray) -> float:
    """``E|δθ|`` for ``δθ ~ N(0, covariance)`` (3x3), from fixed normal draws."""
    root = np.linalg.cholesky(covariance + 1e-300 * np.eye(3))
    # np.linalg.norm(axis=1)'s own steps (square, sum along the row, root),
    # in place: the same numbers, in less than half the time (no temporaries).
    # Its sum along rows of three is (x² + y²) + z², made here column by
    # column: the same bits, in a fifteenth of the time of numpy's reduction
    # (which loops over each short row).
    squared = _MEAN_DRAWS @ root.T
    np.multiply(squared, squared, out=squared)
    lengths = squared[:, 0] + squared[:, 1]
    lengths += squared[:, 2]
    return float(np.mean(np.sqrt(lengths, out=lengths)))


def linear_model(scenario):
    """Noise and prior of the linearised problem: ``(gyro_noise σ_v², σ_u,
    R (3x3), P₀, with_bias)``.

    The prior is what the scenario's filters declare: with a gyro bias model,
    the MEKF's ``P₀`` as ``from_scenario`` builds it (6 states); without one,
    the bias is known to be zero (3 states) and the attitude prior is the
    workshop EKF's, ``4 · initial_covariance · I₃`` (its 4x4 ``P₀`` projected).
    """
    from estimators import ESTIMATORS
    with_bias = scenario.build_gyro().has_bias_model
    R = scenario.star_tracker_attitude_covariance_rad2
    if with_bias:
        # Attitude and gyro bias: a hard iron the MEKF estimates is taken as
        # known here, which only lowers the bound (it stays a lower bound).
        prior = ESTIMATORS["mekf"].from_scenario(scenario).initial_covariance[:6, :6]
    else:
        prior = 4.0 * scenario.initial_covariance * np.eye(3)
    return scenario.gyro_noise, scenario.gyro_filter_bias_random_walk, R, prior, with_bias


def check_bound_inputs(scenario) -> None:
    """Refuse a scenario whose bound cannot be computed: the recursion inverts
    the reading's covariance ``R`` (its information) and the prior ``P₀``, so
    both must be positive definite — a noise-free tracker or a perfectly known
    start has no finite information to add."""
    _, _, R, prior, _ = linear_model(scenario)
    if scenario.star_tracker_model == "none":
        pass
    elif scenario.star_tracker_model == "rotation":
        name, value = "star_tracker_sigma_arcsec", scenario.star_tracker_sigma_arcsec
    else:
        name, value = "star_tracker_noise", scenario.star_tracker_noise
    if scenario.star_tracker_model != "none" and not np.all(np.linalg.eigvalsh(R) > 0):
        raise InvalidParameterError(name, value, "must be > 0 on every axis for the bound "
                                    "(benchmarks.bounds inverts the reading's covariance)")
    if not np.all(np.linalg.eigvalsh(prior) > 0):
        raise InvalidParameterError("initial covariance", np.diag(prior).tolist(),
                                    "must be > 0 on every axis for the bound "
                                    "(benchmarks.bounds inverts the prior)")


def posterior_crb(scenario) -> AttitudeBound:
    """The posterior Cramér–Rao bound along the scenario's true trajectory."""
    check_bound_inputs(scenario)
    noise, bias_rw, R, prior, with_bias = linear_model(scenario)
    truth = simulate_truth(scenario)
    # Each reading at its own time (on the grid, at its step: τ = 0); readings
    # the tracker can never deliver (scheduled outages) give no information.
    tracker = scenario.build_star_tracker()
    steps, offsets = tracker.schedule(scenario.n_steps)
    kept = ~tracker.in_outage(steps * scenario.dt + offsets)
    reading_offset = np.full(scenario.n_steps, np.nan)
    reading_offset[steps[kept]] = offsets[kept]
    states = 6 if with_bias else 3
    # The rate the gyro reads (sampled, or averaged over each step) is the one
    # the filters' transition uses.
    rates = scenario.build_gyro().true_rates(truth.q_true, truth.omega_true_radps)
    R_inverse = np.linalg.inv(R)
    P = prior.copy()
    n = scenario.n_steps
    vector_information = _vector_information(scenario, truth)

    def propagated(P, k, dt):
        phi, q = discrete_error_model(rates[k], dt, noise, bias_rw)
        return phi[:states, :states] @ P @ phi[:states, :states].T + q[:states, :states]

    def updated(P, information_added=R_inverse):
        information = np.linalg.inv(P)
        information[:3, :3] += information_added
        P = np.linalg.inv(information)
        return 0.5 * (P + P.T)

    priors, posteriors = np.empty((n, 3, 3)), np.empty((n, 3, 3))
    for k in range(n):
        priors[k] = P[:3, :3]
        tau = reading_offset[k]
        if tau == 0.0:
            P = updated(P)
        if vector_information is not None and k in vector_information:
            P = updated(P, vector_information[k])
        posteriors[k] = P[:3, :3]
        if tau > 0.0:        # a reading within the step, at t_k + τ
            P = propagated(updated(propagated(P, k, tau)), k, scenario.dt - tau)
        else:
            P = propagated(P, k, scenario.dt)
    return AttitudeBound(time_s=truth.time_s, prior=priors, posterior=posteriors)


def _vector_information(scenario, truth) -> dict | None:
    r"""Step → the vector readings' information about the attitude at that
    step, :math:`\sum_i \sigma_i^{-2}(|b_i|^2 I_3 - b_i b_i^\mathsf{T})` along
    the truth, at the steps each sensor reads, or None. The schedule is that
    of seed 0's readings: for every sensor but the coarse sun sensors it
    depends on the truth alone (rate, eclipse, field of view); theirs, and
    their variance, on which faces read lit, which noise changes only for a
    face at the terminator."""
    if not scenario.has_vector_sensors:
        return None
    from benchmarks.simulation import scenario_references, vector_readings
    from sensors.vector import to_body
    information = {}
    for readings in vector_readings(scenario, truth.q_true, scenario_references(scenario), 0):
        steps = np.flatnonzero(readings.available)
        b = to_body(truth.q_true[steps], readings.reference[steps])
        for k, vector, variance in zip(steps, b, readings.variance[steps]):
            term = (vector @ vector * np.eye(3) - np.outer(vector, vector)) / variance
            information[k] = information.get(k, 0.0) + term
    return information


def periodic_steady_state(gyro_noise: float, dt: float, steps_between: int, R: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Per phase ``j = 0 … m-1`` of the star tracker period, the steady-state
    attitude covariance (3x3, rad²) before and after that step's reading.

    The lifted model over one period: ``A = I``, ``Q_m = m σ_v² Δt I``,
    ``H = I`` (no bias random walk, rotation per period neglected).
    """
    q_step = gyro_noise * dt * np.eye(3)
    P_reading_prior = solve_discrete_are(np.eye(3), np.eye(3), steps_between * q_step, R)
    P_reading_posterior = P_reading_prior - P_reading_prior @ np.linalg.solve(
        P_reading_prior + R, P_reading_prior)
    phases = np.arange(steps_between)
    posterior = P_reading_posterior + phases[:, None, None] * q_step
    prior = posterior.copy()
    prior[0] = P_reading_prior
    return prior, posterior
