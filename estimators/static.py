r"""Static attitude determination: a Wahba solution at every step with two
or more non-parallel vector readings, and the gyro between them.

Each of the six solvers of :mod:`estimators.wahba` is a registry estimator
(``triad``, ``q-method``, ``quest``, ``esoq2``, ``foam``, ``svd``) with the
common interface. At a step whose vector readings
(:class:`sensors.vector.VectorObservation`) hold two directions at least
``min_separation_deg`` apart, the estimate is that step's solution and its
covariance the solver's (Shuster's :math:`[\sum_i \sigma_i^{-2}(I_3 - b_i
b_i^\mathsf{T})]^{-1}` for the optimal solvers, Shuster & Oh's for TRIAD;
:mod:`estimators.wahba`), each direction weighed by
:math:`a_i = \sigma_i^{-2}` with :math:`\sigma_i` its angular noise (a
magnetometer's σ in nT over the field's strength), the magnetometer's times
``magnetometer_weight`` (1 by default: tunable, since a magnetometer's real
error is often its model's, not its noise; only the ratios of the weights
move the solution, the covariance keeps each σ). Nothing of earlier steps
is kept: that is what makes it static, and what a filter adds.

Between solutions (one sensor in eclipse, or none), ``between`` says what
it does:

* ``"propagate"`` (the default): the last estimate is carried by the gyro,
  :math:`\hat q_{k+1} = \hat q_k \otimes \delta q(\tilde\omega_k \Delta t)`,
  and its covariance grows by the gyro's angle noise,
  :math:`P \leftarrow \Phi P \Phi^\mathsf{T} + \sigma_v^2 \Delta t\, I_3` with
  :math:`\Phi` the step's rotation. The gyro bias is not estimated, so an
  uncompensated bias makes the covariance optimistic in long gaps.
* ``"hold"``: the last solution is held, with its covariance (which then
  understates the error as the body turns).

Star tracker readings are not used: these are the vector-only solutions.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import IDENTITY, quat_from_rotvec, quat_multiply, rotation_matrix
from dynamics.validation import finite_number, one_of
from estimators import sensing, triad, wahba
from estimators.base import AttitudeEstimator, axis_sigmas, finite_state
from estimators.settings import DEFAULT_ATTITUDE_SIGMA_RAD, DEFAULT_DT_S, DEFAULT_GYRO_NOISE
from estimators.tunable import MAGNETOMETER_WEIGHT

BETWEEN = ("propagate", "hold")


class StaticAttitude(AttitudeEstimator):
    """A Wahba solver as an estimator (module docstring); subclasses name the solver.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,)
        The estimate before the first solution.
    gyro_noise : float
        σ_v², rad²/s: the covariance's growth between solutions.
    initial_attitude_sigma_rad : float or (3,)
        The covariance before the first solution, rad per axis.
    between : {"propagate", "hold"}
        What the estimate does between solutions.
    min_separation_deg : float
        Two directions closer than this (or to its supplement) count as
        one: no solution from them alone.
    magnetometer_weight : float
        A factor on the magnetometer's weight σ⁻² against
        the other sensors'.
    on_invalid : {"raise", "skip"}
    """

    uses_vector_readings = True
    reads = frozenset(sensing.VECTOR_SENSORS)
    needs = sensing.TWO_DIRECTIONS
    tunable = (MAGNETOMETER_WEIGHT,)
    solver = staticmethod(wahba.svd)
    scenario_defaults = {"initial_attitude": "initial_state", "gyro_noise": "gyro_noise"}

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 gyro_noise: float = DEFAULT_GYRO_NOISE,
                 initial_attitude_sigma_rad=DEFAULT_ATTITUDE_SIGMA_RAD, between: str = "propagate",
                 min_separation_deg: float = 1.0, magnetometer_weight: float = 1.0,
                 on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        self.gyro_noise = finite_number("gyro_noise", gyro_noise, minimum=0.0)
        self.initial_covariance = np.diag(axis_sigmas("initial_attitude_sigma_rad",
                                                      initial_attitude_sigma_rad) ** 2)
        self.between = one_of("between", between, BETWEEN)
        separation = finite_number("min_separation_deg", min_separation_deg, minimum=0.0)
        self.min_sine = math.sin(math.radians(min(separation, 90.0)))
        self.magnetometer_weight = finite_number("magnetometer_weight", magnetometer_weight,
                                                 strictly_positive=True)
        self.reset()

    def reset(self) -> None:
        self.q_hat = self.initial_attitude.copy()
        self.P = self.initial_covariance.copy()
        #: Steps with a solution since the last reset.
        self.solutions = 0

    @property
    def attitude(self) -> np.ndarray:
        return self.q_hat.copy()

    def readings_used(self) -> int:
        """The steps it solved at: without one, its estimate is the gyro's
        from its start (no two separated directions at any one step)."""
        return self.solutions

    @property
    def attitude_covariance(self) -> np.ndarray:
        return self.P.copy()

    def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()) -> np.ndarray:
        solved = self.solve(vectors) if len(vectors) >= 2 else None
        if solved is not None:
            self.q_hat, self.P = solved
            self.solutions += 1
        estimate = self.q_hat.copy()
        if self.between == "propagate":
            self._propagate(omega_meas_radps)
        return estimate

    def solve(self, vectors) -> tuple[np.ndarray, np.ndarray] | None:
        """The solution and its covariance from one step's vector readings,
        or None without two separated directions."""
        vectors = [v for v in vectors if np.any(np.asarray(v.body, dtype=float))]
        if len(vectors) < 2:
            return None
        body = np.array([np.asarray(v.body, dtype=float) for v in vectors])
        reference = np.array([np.asarray(v.reference, dtype=float) for v in vectors])
        reference_norm = np.linalg.norm(reference, axis=1)
        body = body / np.linalg.norm(body, axis=1, keepdims=True)
        reference = reference / reference_norm[:, None]
        sigmas = np.sqrt([v.variance for v in vectors]) / reference_norm
        if not _separated(body, reference, self.min_sine):
            return None
        factors = [self.magnetometer_weight if v.sensor == "magnetometer" else 1.0
                   for v in vectors]
        weights = np.asarray(factors) / sigmas ** 2
        return self.solution(body, reference, weights), self.covariance(body, reference, sigmas)

    def solution(self, body, reference, weights) -> np.ndarray:
        """The solver's quaternion for unit vectors and their weights."""
        return self.solver(body, reference, weights)

    def covariance(self, body, reference, sigmas) -> np.ndarray:
        """The solution's body-frame covariance, rad² (Shuster's)."""
        return wahba.wahba_covariance(body, sigmas)

    def _propagate(self, omega_meas_radps) -> None:
        rotation = np.asarray(omega_meas_radps, dtype=float) * self.dt
        step = quat_from_rotvec(rotation)
        q = quat_multiply(self.q_hat, step)
        self.q_hat = q / np.sqrt(q @ q)
        phi = rotation_matrix(step).T          # the body-frame error turns with the body
        self.P = phi @ self.P @ phi.T + self.gyro_noise * self.dt * np.eye(3)

    def state_is_finite(self) -> bool:
        return finite_state(self.q_hat, self.P)


def _separated(body: np.ndarray, reference: np.ndarray, min_sine: float) -> bool:
    """Whether two observations are at least ``asin(min_sine)`` apart in both
    frames (two readings of one direction, the Sun's, do not fix an attitude)."""
    for i in range(len(body)):
        for j in range(i + 1, len(body)):
            if triad.separated(body[i], body[j], min_sine) and \
                    triad.separated(reference[i], reference[j], min_sine):
                return True
    return False


class TRIAD(StaticAttitude):
    """TRIAD on the two most accurate separated directions (:func:`estimators.triad.triad`)."""

    name = "triad"
    label = "TRIAD"

    def solution(self, body, reference, weights) -> np.ndarray:
        return triad.triad(body, reference, weights, self.min_sine)

    def covariance(self, body, reference, sigmas) -> np.ndarray:
        first, second = triad.triad_pair(body, reference, 1.0 / sigmas ** 2, self.min_sine)
        return triad.triad_covariance(body, sigmas, first, second)

    def run_batch(self, omega_meas_radps, vectors) -> np.ndarray | None:
        """``run``'s estimates at once for two vector sensors read at every
        sample (no star tracker): each sample's TRIAD where both readings
        are non-zero and separated in both frames (:meth:`solve`'s weights
        pick the anchor), and between those, the steps ``run`` takes
        (:meth:`_propagate`, or the held estimate). None otherwise (the
        per-run path then)."""
        if len(vectors) != 2 or not all(np.all(v.available) for v in vectors):
            return None
        units, weights, nonzero = [], [], []
        for v in vectors:
            body, reference = np.asarray(v.body, float), np.asarray(v.reference, float)
            body_norm, reference_norm = (np.linalg.norm(x, axis=1) for x in (body, reference))
            nonzero.append(body_norm > 0)
            units.append((body / np.where(body_norm > 0, body_norm, 1.0)[:, None],
                          reference / reference_norm[:, None]))
            factor = self.magnetometer_weight if v.sensor == "magnetometer" else 1.0
            weights.append(factor * reference_norm ** 2 / np.asarray(v.variance, float))
        (b1, r1), (b2, r2) = units
        solved = nonzero[0] & nonzero[1]
        for u, w in ((b1, b2), (r1, r2)):
            solved &= np.linalg.norm(np.cross(u, w), axis=1) > max(self.min_sine, 1e-12)
        second = (weights[1] > weights[0])[:, None]     # the heavier anchors; ties, the first
        estimates = np.empty((len(b1), 4))
        estimates[solved] = triad.triad_attitudes(
            *(np.where(second, y, x)[solved] for x, y in ((b1, b2), (b2, b1), (r1, r2), (r2, r1))))
        self.reset()
        for k in np.flatnonzero(~solved):
            self.q_hat = self.initial_attitude.copy() if k == 0 else estimates[k - 1].copy()
            if k > 0 and self.between == "propagate":
                self._propagate(omega_meas_radps[k - 1])
            estimates[k] = self.q_hat
        return estimates


class DavenportQ(StaticAttitude):
    """Davenport's q-method (:func:`estimators.wahba.davenport_q`)."""

    name = "q-method"
    label = "q-method"
    solver = staticmethod(wahba.davenport_q)


class QUEST(StaticAttitude):
    """QUEST (:func:`estimators.wahba.quest`)."""

    name = "quest"
    label = "QUEST"
    solver = staticmethod(wahba.quest)


class ESOQ2(StaticAttitude):
    """ESOQ2 (:func:`estimators.wahba.esoq2`)."""

    name = "esoq2"
    label = "ESOQ2"
    solver = staticmethod(wahba.esoq2)


class FOAM(StaticAttitude):
    """FOAM (:func:`estimators.wahba.foam`)."""

    name = "foam"
    label = "FOAM"
    solver = staticmethod(wahba.foam)


class SVD(StaticAttitude):
    """The SVD solution, scipy's ``Rotation.align_vectors`` (:func:`estimators.wahba.svd`)."""

    name = "svd"
    label = "SVD"
    solver = staticmethod(wahba.svd)


STATIC_ESTIMATORS = (TRIAD, DavenportQ, QUEST, ESOQ2, FOAM, SVD)
