"""Wahba's problem: the six solvers against each other, scipy's
``align_vectors``, the ``ahrs`` package, and Shuster's covariance."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from dynamics.quaternion import quat_multiply, quat_conjugate, rotation_matrix, rotvec_from_quat
from estimators import ESTIMATORS, wahba
from sensors.vector import VectorObservation

OPTIMAL = ("q-method", "quest", "esoq2", "foam", "svd")


def same_attitude(q1, q2) -> float:
    """The sign-invariant distance of two unit quaternions (component-wise)."""
    return float(min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max()))


def noise_free_case(rng, n, q):
    body = rng.standard_normal((n, 3))
    body /= np.linalg.norm(body, axis=1, keepdims=True)
    return body, body @ rotation_matrix(q).T, rng.uniform(0.1, 1.0, n)


@pytest.mark.parametrize("q", [
    Rotation.random(random_state=1).as_quat(scalar_first=True),
    np.array([0.0, 1.0, 0.0, 0.0]),                    # 180° about x: QUEST's hard case
    np.array([0.0, 0.0, 0.6, 0.8]),                    # 180° about an oblique axis
    np.array([1.0, 0.0, 0.0, 0.0]),
])
def test_every_solver_returns_the_truth_on_noise_free_data(q, rng):
    body, reference, weights = noise_free_case(rng, 4, q)
    for name, solver in wahba.SOLVERS.items():
        assert same_attitude(solver(body, reference, weights), q) < 1e-12, name


def test_the_optimal_solvers_agree_with_align_vectors_on_noisy_data(rng):
    for trial in range(50):
        q = Rotation.random(random_state=trial).as_quat(scalar_first=True)
        body, reference, weights = noise_free_case(rng, 3 + trial % 4, q)
        body = body + 0.01 * rng.standard_normal(body.shape)
        body /= np.linalg.norm(body, axis=1, keepdims=True)
        expected = wahba.svd(body, reference, weights)
        for name in OPTIMAL:
            assert same_attitude(wahba.SOLVERS[name](body, reference, weights), expected) < 1e-9


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(2, 8),
       noise=st.sampled_from([0.0, 1e-6, 1e-3, 0.05]))
def test_the_optimal_solvers_minimise_the_same_loss_for_all_inputs(seed, count, noise):
    # For every attitude and observation set, each optimal solver's loss is
    # the q-method's (the eigenvalue solution) to 1e-9 of the total weight.
    rng = np.random.default_rng(seed)
    q = Rotation.random(random_state=seed % 1000).as_quat(scalar_first=True)
    body, reference, weights = noise_free_case(rng, count, q)
    body = body + noise * rng.standard_normal(body.shape)
    body /= np.linalg.norm(body, axis=1, keepdims=True)
    if np.linalg.matrix_rank(body, tol=1e-3) < 2:
        return                                  # parallel observations fix no attitude
    best = wahba.loss(wahba.davenport_q(body, reference, weights), body, reference, weights)
    for name in OPTIMAL:
        value = wahba.loss(wahba.SOLVERS[name](body, reference, weights), body, reference,
                           weights)
        assert value == pytest.approx(best, abs=1e-9 * weights.sum())


def test_the_solvers_agree_with_the_ahrs_package_on_random_cases():
    # ahrs (a test extra) fixes the references: gravity [0, 0, 1] and a
    # magnetic field [cos d, 0, sin d] of dip d. Its QUEST and Davenport
    # quaternions are body-to-reference as ours (Davenport up to sign); its
    # TRIAD returns the reference-to-body rotation, our TRIAD's inverse.
    filters = pytest.importorskip("ahrs.filters")
    rng = np.random.default_rng(11)
    for trial in range(20):
        q = Rotation.random(random_state=100 + trial).as_quat(scalar_first=True)
        dip = rng.uniform(-80, 80)
        reference = np.array([[0.0, 0.0, 1.0],
                              [math.cos(math.radians(dip)), 0.0, math.sin(math.radians(dip))]])
        body = reference @ rotation_matrix(q) + 0.01 * rng.standard_normal((2, 3))
        body /= np.linalg.norm(body, axis=1, keepdims=True)
        ours = wahba.quest(body, reference, np.array([0.5, 0.5]))
        theirs = filters.QUEST(magnetic_dip=reference[1], weights=np.array([0.5, 0.5])
                               ).estimate(body[0], body[1])
        assert same_attitude(ours, np.asarray(theirs)) < 1e-9
        theirs = filters.Davenport(magnetic_dip=dip, weights=np.array([1.0, 1.0]),
                                   gravity=1.0).estimate(body[0], body[1])
        assert same_attitude(wahba.davenport_q(body, reference, np.ones(2)),
                             np.asarray(theirs)) < 1e-9
        theirs = filters.TRIAD(v1=reference[0], v2=reference[1], representation="quaternion"
                               ).estimate(body[0], body[1], representation="quaternion")
        assert same_attitude(wahba.triad(body, reference, np.array([2.0, 1.0])),
                             quat_conjugate(np.asarray(theirs))) < 1e-9


def _error_angles(solver, q, body_true, reference, sigmas, draws, rng):
    """Body-frame errors δθ (q_true = q̂ ⊗ δq(δθ)) of ``draws`` noisy solutions."""
    errors = np.empty((draws, 3))
    for i in range(draws):
        tilt = sigmas[:, None] * rng.standard_normal(body_true.shape)
        tilt -= np.sum(tilt * body_true, axis=1, keepdims=True) * body_true
        body = np.array([Rotation.from_rotvec(t).apply(b) for t, b in zip(tilt, body_true)])
        estimate = solver(body, reference, 1.0 / sigmas ** 2)
        errors[i] = rotvec_from_quat(quat_multiply(quat_conjugate(estimate), q))
    return errors


@pytest.mark.parametrize("name", ["quest", "triad"])
def test_the_covariance_is_the_sample_covariance_of_the_error(name, rng):
    # N = 3000 noisy solutions of one geometry (directions 60° apart and a
    # third, σ of 1 mrad to 5 mrad): the NEES with the solver's covariance,
    # summed, is χ²(3N); bounds at 99.9 % (two-sided).
    q = Rotation.random(random_state=3).as_quat(scalar_first=True)
    body_true = np.array([[1.0, 0.0, 0.0], [0.5, math.sqrt(3) / 2, 0.0], [0.0, 0.6, 0.8]])
    sigmas = np.array([1e-3, 3e-3, 5e-3])
    if name == "triad":
        body_true, sigmas = body_true[:2], sigmas[:2]
    reference = body_true @ rotation_matrix(q).T
    estimator = ESTIMATORS[name](dt=1.0)
    covariance = estimator.covariance(body_true, reference, sigmas)
    if name == "quest":
        shuster = np.linalg.inv(sum((np.eye(3) - np.outer(b, b)) / s ** 2
                                    for b, s in zip(body_true, sigmas)))
        assert np.allclose(covariance, shuster, rtol=1e-12)
    draws = 3000
    errors = _error_angles(wahba.SOLVERS[name], q, body_true, reference, sigmas, draws, rng)
    total = np.einsum("ni,ij,nj->", errors, np.linalg.inv(covariance), errors)
    low, high = chi2.ppf([0.0005, 0.9995], 3 * draws)
    assert low < total < high


def test_a_static_estimator_solves_with_two_directions_and_propagates_between():
    q = Rotation.random(random_state=8).as_quat(scalar_first=True)
    r1, r2 = np.array([1.0, 0, 0]), np.array([0.0, 1.0, 0])
    A = rotation_matrix(q)
    observations = (VectorObservation(A.T @ r1 * 30000.0, r1 * 30000.0, 100.0 ** 2,
                                      "magnetometer"),
                    VectorObservation(A.T @ r2, r2, 1e-6, "sun_sensor", 2))
    estimator = ESTIMATORS["quest"](dt=1.0, gyro_noise=1e-10)
    estimate = estimator.step(np.zeros(3), None, vectors=observations)
    assert same_attitude(estimate, q) < 1e-12 and estimator.solutions == 1
    # One direction: no solution, the gyro carries the estimate and P grows.
    P = estimator.attitude_covariance
    omega = np.array([0.0, 0.0, 0.01])
    carried = estimator.step(omega, None, vectors=observations[:1])
    assert same_attitude(carried, q) < 1e-12          # the step's estimate, then propagated
    assert estimator.solutions == 1
    assert np.trace(estimator.attitude_covariance) > np.trace(P)
    # Two readings of one direction (the Sun, by two sensors) are not a pair.
    both_suns = (observations[1], VectorObservation(A.T @ r2, r2, 1e-4, "coarse_sun_sensors"))
    estimator.step(omega, None, vectors=both_suns)
    assert estimator.solutions == 1


def test_hold_keeps_the_last_solution():
    estimator = ESTIMATORS["svd"](dt=1.0, between="hold")
    first = estimator.step(np.array([0.1, 0.0, 0.0]), None)
    second = estimator.step(np.array([0.1, 0.0, 0.0]), None)
    assert np.array_equal(first, second)
