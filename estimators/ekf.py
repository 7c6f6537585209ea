r"""Additive extended Kalman filter on the four quaternion components.

The workshop's EKF (the workshop model, "The three estimators", item 3) treats the
quaternion as an ordinary 4-vector, built on filterpy's
:class:`~filterpy.kalman.ExtendedKalmanFilter` with ``dim_x = dim_z = 4``:

.. math::

    \text{predict:}\quad \hat x_{k+1|k} = f(\hat x_{k|k}, \tilde\omega_k), \qquad
        P_{k+1|k} = F_k P_{k|k} F_k^\mathsf{T} + Q, \qquad
        F_k = \left.\frac{\partial f}{\partial q}\right|_{\hat x_{k|k}}

    \text{update:}\quad h(q) = q,\ H = I_4, \qquad
        K = P H^\mathsf{T} (H P H^\mathsf{T} + R)^{-1}, \qquad
        \hat x_{k|k} = \hat x_{k|k-1} + K (z_k - \hat x_{k|k-1}),

    \qquad P_{k|k} = (I - K H) P (I - K H)^\mathsf{T} + K R K^\mathsf{T}
    \quad\text{(Joseph form, as filterpy does)},

with ``f`` and its exact Jacobian from :mod:`estimators.model`,
``Q = exp(pc_exponent) I₄``, ``R = measurement_covariance``.

Order within step ``k`` (the Simulink filter block with "use current
measurement" off): output the prior ``x̂[k|k-1]`` as ``q̂[k]``; correct with
``z_k`` if a reading is available; then predict to ``x̂[k+1|k]`` with
``ω̃_k``. ``output="posterior"`` outputs ``x̂[k|k]`` instead. With
``rate_interpolation="end"`` (an IMU's reading, the rate over the step
before it) the predict comes first: to ``x̂[k|k-1]`` with ``ω̃_k``, then the
output and the correction.

filterpy's own ``predict`` is linear (``x = F x``); here the filter's
``predict_x`` is overridden (:class:`~estimators.ekf_filter.WorkshopModelEKF`) so the state goes
through the nonlinear ``f`` and ``F`` is recomputed from the exact Jacobian
at every step (filterpy issue #181 is about users having to discover exactly
this). The state is kept as a 1-D ``(4,)`` array, so ``x``, ``x_prior`` and
``x_post`` are 1-D too.

This additive filter lets the estimate leave the unit sphere between steps
and ignores the quaternion's norm constraint in ``P``; the multiplicative EKF
of Markley & Crassidis (2014, §6.2), :mod:`estimators.mekf`, is the standard
remedy.

**Vector measurements** (its own Jacobian, on the four components): a
reading :math:`b = A(q)^\mathsf{T} r + v` (:mod:`sensors.vector`) is
predicted from the normalised state :math:`n = x / \lVert x\rVert`,
:math:`h(x) = A(n)^\mathsf{T} r` with, for :math:`n = (w, u)`,

.. math:: A(n)^\mathsf{T} r = (w^2 - u\cdot u)\, r + 2 (u \cdot r)\, u - 2 w\, u \times r,

    \frac{\partial h}{\partial x} = \Bigl[\, 2 w r - 2 u \times r \ \ \Big|\ \
        2 (u\cdot r) I_3 + 2 u r^\mathsf{T} - 2 r u^\mathsf{T} + 2 w [r\times] \,\Bigr]
        \frac{I_4 - n n^\mathsf{T}}{\lVert x\rVert},

:math:`R = \sigma^2 I_3`, one filterpy update per vector. Gating
(``gate_probability``) tests each reading's NIS, :math:`S = H P
H^\mathsf{T} + R`, before its update.

To compare it with filters whose error state is a body-frame small angle,
its 4x4 ``P`` is projected (:attr:`QuaternionEKF.attitude_covariance`): with
:math:`q = \hat q \otimes \delta q(\delta\theta) \approx \hat q + \tfrac12
\Xi(\hat q)\,\delta\theta` and :math:`\Xi^\mathsf{T}\Xi = I_3`,
:math:`\Xi^\mathsf{T}\hat q = 0` for a unit :math:`\hat q`,

.. math:: \delta\theta = 2\,\Xi(\hat q)^\mathsf{T}\,\delta q, \qquad
          P_{\theta} = 4\,\Xi(\hat q)^\mathsf{T} P\, \Xi(\hat q),

evaluated at the normalised estimate; the component of ``P`` along
:math:`\hat q` (the norm direction, which is no attitude) drops out.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import IDENTITY, kinematics_matrix, skew, to_body_frame
from dynamics.validation import (
    InvalidParameterError,
    boolean,
    covariance_matrix,
    finite_number,
    one_of,
    process_exponent,
)
from estimators.base import (OUTPUTS, AttitudeEstimator, KalmanEstimator, finite_state,
                             gate_probability_setting)
from estimators.sampled_rate import SampledRate
from estimators.settings import DEFAULT_DT_S
from estimators.tunable import GATE_PROBABILITY, MEASUREMENT_SCALE, Tunable

_IDENTITY_4 = np.eye(4)


def _measurement_jacobian(_x: np.ndarray) -> np.ndarray:
    """``H = ∂h/∂q = I₄``."""
    return _IDENTITY_4


def _measurement_function(x: np.ndarray) -> np.ndarray:
    """``h(q) = q``: the star tracker measures the quaternion itself."""
    return x


def vector_prediction(x: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``h(x) = A(x/|x|)ᵀ r``: the body vector the state predicts."""
    return to_body_frame(x / np.sqrt(x @ x), reference)


def vector_jacobian(x: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``∂h/∂x`` (3x4) of :func:`vector_prediction` (module docstring)."""
    norm = np.sqrt(x @ x)
    n = x / norm
    w, u, r = n[0], n[1:], reference
    quadratic = np.empty((3, 4))
    quadratic[:, 0] = 2.0 * w * r - 2.0 * np.cross(u, r)
    quadratic[:, 1:] = (2.0 * (u @ r) * np.eye(3) + 2.0 * np.outer(u, r) - 2.0 * np.outer(r, u)
                        + 2.0 * w * skew(r))
    return quadratic @ (np.eye(4) - np.outer(n, n)) / norm


#: The rates over a step the EKF takes (its kernel has these two; the
#: trapezoid is the six-state filters').
EKF_RATE_INTERPOLATIONS = ("hold", "end")


class QuaternionEKF(SampledRate, KalmanEstimator):
    """The workshop's additive quaternion EKF (on a filterpy ``ExtendedKalmanFilter``).

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    pc_exponent : float
        Process covariance ``Q = exp(pc_exponent) I₄`` (natural exponent).
    measurement_covariance : float, (4,) or (4, 4)
        ``R``; a scalar means ``R = value · I₄``.
    initial_attitude : (4,) array-like
        ``x̂[0|-1]``, scalar-first; normalised. (``initial_state``, its
        former name, is still accepted.)
    initial_covariance : float
        ``P[0|-1] = initial_covariance · I₄``; must be > 0.
    output : {"prior", "posterior"}
        Which estimate :meth:`step` returns: the workshop's prior
        ``x̂[k|k-1]`` (default) or the corrected ``x̂[k|k]``.
    align_sign : bool
        Flip a reading ``z`` to ``-z`` when ``x̂ · z < 0`` before the update
        (default): ``h(q) = q`` is not sign-invariant, and a tracker that
        reports the ``w >= 0`` representative makes the raw innovation nearly
        ``-2 x̂`` where the true ``w`` crosses zero (``align_sign=False``
        shows it; the workshop's readings, on the prediction's side, are unchanged).
    gate_probability : float or None
        Innovation gating (see :class:`~estimators.MultiplicativeEKF`); None: off.
    rate_interpolation : {"hold", "end"}
        A reading held over the step after it (the workshop's) or the rate over
        the step before it (an IMU's; :mod:`estimators.sampled_rate`).
    on_invalid : {"raise", "skip"}
        What to do with an unusable measurement (see
        :meth:`~estimators.AttitudeEstimator.step`).

    After each :meth:`step` the filterpy object :attr:`filter` (a
    :class:`~estimators.ekf_filter.WorkshopModelEKF`) is there to inspect:
    ``x_prior``/``P_prior``, ``x_post``/``P_post``, ``y``, ``S``, ``K``,
    ``F``, ``Q = exp(pc_exponent) I₄`` and ``R``.
    """

    name = "ekf"
    label = "EKF"
    scenario_defaults = {"initial_attitude": "initial_state", "pc_exponent": "pc_exponent",
                         "measurement_covariance": "measurement_covariance",
                         "initial_covariance": "initial_covariance"}
    owned_fields = ("pc_exponent", "measurement_covariance", "initial_covariance")
    #: Q's exponent (``pc_exponent``: Q = e^pc I₄, searched ±8 about its
    #: default), a factor on R, and the gate.
    tunable = (Tunable("pc_exponent", "linear", (-700.0, 700.0), span=8.0,
                       description="ln of Q's variance per quaternion component"),
               MEASUREMENT_SCALE, GATE_PROBABILITY)

    #: The MEKF's default attitude prior, 0.1 rad per axis, in quaternion
    #: units ((σ/2)² per component): the derived P₀.
    DERIVED_INITIAL_COVARIANCE = (0.1 / 2.0) ** 2
    #: The smallest derived Q or R per component (a noise-free gyro or tracker).
    MIN_DERIVED_VARIANCE = 1e-30

    @classmethod
    def derived_fields(cls, scenario) -> dict:
        r"""The EKF's settings for ``scenario`` where it leaves them unset.

        On the workshop's sensors (``scenario.is_workshop_sensors``), the
        exercise's: :math:`Q = e^{-8.7} I_4`, :math:`R = I_4`,
        :math:`P_0 = 10^{-12} I_4`. Otherwise, from the sensors, in quaternion
        units (:math:`\delta q \approx \tfrac12 \Xi(q)\,\delta\theta`, so an
        angle variance :math:`s` per axis is :math:`s/4` per component):

        * ``measurement_covariance`` :math:`R = \tfrac{1}{12}\operatorname{tr}(R_\theta)\, I_4`,
          the tracker's body-frame covariance :math:`R_\theta` averaged over
          the three axes. A constant 4x4 ``R`` cannot follow an anisotropic
          error fixed in the body (its quaternion image turns with the
          attitude); the MEKF, whose ``R`` is :math:`R_\theta` itself, can.
        * ``pc_exponent`` :math:`= \ln\bigl(\tfrac14(\sigma_v^2\Delta t +
          \sigma_u^2\Delta t^3/3)\bigr)`: the angle the gyro's noise and bias
          walk add in one step (M&C 2014, eq. 6.93's attitude block). This
          filter has no bias state: a constant bias is not in its model.
        * ``initial_covariance`` :math:`= (0.1/2)^2`, the MEKF's default prior.
        """
        if scenario.is_workshop_sensors:
            return {"pc_exponent": -8.7, "measurement_covariance": np.eye(4),
                    "initial_covariance": 1e-12}
        R_theta = scenario.star_tracker_attitude_covariance_rad2
        dt, su = scenario.dt, scenario.gyro_filter_bias_random_walk
        per_step = (scenario.gyro_noise * dt + su * su * dt ** 3 / 3.0) / 4.0
        if not math.isfinite(per_step):
            raise InvalidParameterError(
                "gyro_bias_random_walk", su, "(the filters' equivalent σ_u) makes the "
                "angle noise of one step overflow; the EKF's Q cannot be derived from it")
        per_component = max(np.trace(R_theta) / 12.0, cls.MIN_DERIVED_VARIANCE)
        return {"pc_exponent": math.log(max(per_step, cls.MIN_DERIVED_VARIANCE)),
                "measurement_covariance": per_component * np.eye(4),
                "initial_covariance": cls.DERIVED_INITIAL_COVARIANCE}

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """The scenario's settings, and the output: the workshop's prior on its
        sensors, the posterior (as the MEKF and USQUE give) on any other."""
        settings = super().settings_from_scenario(scenario)
        settings["output"] = "prior" if scenario.is_workshop_sensors else "posterior"
        return settings

    def __init__(self, *, dt: float = DEFAULT_DT_S, pc_exponent: float = -8.7,
                 measurement_covariance=1.0, initial_attitude=IDENTITY,
                 initial_covariance: float = 1e-12, output: str = "prior",
                 align_sign: bool = True, gate_probability: float | None = None,
                 rate_interpolation: str = "hold", on_invalid: str = "raise",
                 initial_state=None):
        # initial_state, the former name of initial_attitude, wins when given
        # (an [estimators.ekf] section's over the scenario's default).
        if initial_state is not None:
            initial_attitude = initial_state
        AttitudeEstimator.__init__(self, dt=dt, initial_attitude=initial_attitude,
                                   on_invalid=on_invalid)
        from estimators.ekf_filter import WorkshopModelEKF  # here, not at the top: building a scenario (and --help) needs no filterpy
        self.filter = WorkshopModelEKF(self.dt)
        self.align_sign = boolean("align_sign", align_sign)
        self.gate_probability = gate_probability_setting(gate_probability)
        self.pc_exponent = process_exponent("pc_exponent", pc_exponent)
        self.initial_covariance = finite_number("initial_covariance", initial_covariance,
                                                strictly_positive=True)
        self.output = one_of("output", output, OUTPUTS)
        self.rate_interpolation = one_of("rate_interpolation", rate_interpolation,
                                         EKF_RATE_INTERPOLATIONS)
        self.filter.R = covariance_matrix("measurement_covariance", measurement_covariance)
        self.filter.Q = math.exp(self.pc_exponent) * _IDENTITY_4
        self.reset()

    def reset(self) -> None:
        self._reset_filter(self.initial_attitude.copy(), self.initial_covariance * _IDENTITY_4)
        self._restart_rates()
        self._record()

    def _record(self) -> None:
        # filterpy replaces x and P with new arrays, so keeping references is a snapshot.
        x = self.filter.x
        if self.output == "posterior":
            # The additive update leaves the unit sphere; the attitude it
            # estimates is the direction of x (the prior is f's, already unit).
            x = x / math.sqrt(x @ x)
        self._output = (x, self.filter.P)

    @property
    def attitude(self) -> np.ndarray:
        """The estimate :meth:`step` last returned, ``(4,)``: the prior as
        ``f`` gives it (unit), or the posterior normalised."""
        return self._output[0].copy()

    @property
    def attitude_covariance(self) -> np.ndarray:
        """``4 Ξ(q̂)ᵀ P Ξ(q̂)`` (rad²) for the last estimate and its ``P``
        (see the module docstring)."""
        x, P = self._output
        xi = kinematics_matrix(x / np.sqrt(x @ x))
        return 4.0 * xi.T @ P @ xi

    def state_is_finite(self) -> bool:
        return finite_state(self.filter.x, self.filter.P)

    def correct(self, star_tracker_quat: np.ndarray) -> None:
        """filterpy's update with ``H = I₄``, the reading sign-aligned first if asked."""
        reading = np.asarray(star_tracker_quat, dtype=float)
        if self.align_sign and reading @ self.filter.x < 0:
            reading = -reading
        if self.gate_probability is not None and not self.accepts(
                reading - self.filter.x, self.filter.P + self.filter.R, 4, "star_tracker"):
            return
        self.filter.update(reading, _measurement_jacobian, _measurement_function)

    def correct_vector(self, observation) -> None:
        """filterpy's update with one vector reading and its Jacobian (module docstring)."""
        reference = np.asarray(observation.reference, dtype=float)
        R = observation.variance * np.eye(3)
        z = np.asarray(observation.body, dtype=float)
        if self.gate_probability is not None:
            H = vector_jacobian(self.filter.x, reference)
            if not self.accepts(z - vector_prediction(self.filter.x, reference),
                                H @ self.filter.P @ H.T + R, observation.dof,
                                observation.sensor):
                return
        self.filter.update(z, vector_jacobian, vector_prediction, R=R, args=(reference,),
                           hx_args=(reference,))

    def _without_reading(self) -> None:
        if self.output == "posterior":
            self.filter.x_post, self.filter.P_post = self.filter.x.copy(), self.filter.P.copy()

    def propagate(self, omega_meas_radps: np.ndarray, dt: float | None = None) -> None:
        """``x ← f(x, ω̃)``, ``P ← F P Fᵀ + Q`` (filterpy's predict); over part
        of a step, ``dt`` seconds, with ``Q`` scaled by ``dt / Δt`` (white
        noise adds variance in proportion to time)."""
        if dt is None:
            self.filter.predict(u=omega_meas_radps)
            return
        full_q = self.filter.Q
        self.filter.dt, self.filter.Q = dt, full_q * (dt / self.dt)
        try:
            self.filter.predict(u=omega_meas_radps)
        finally:
            self.filter.dt, self.filter.Q = self.dt, full_q
