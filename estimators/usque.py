r"""USQUE: the unscented quaternion estimator, on filterpy's ``UnscentedKalmanFilter``.

Crassidis & Markley, "Unscented Filtering for Spacecraft Attitude
Estimation", *J. Guidance, Control, and Dynamics* 26(4), 2003 (USQUE);
Markley & Crassidis 2014, §6.3. The filter's state is

.. math:: x = \begin{bmatrix}\delta p \\ \beta\end{bmatrix}, \qquad
          q = \hat q \otimes \delta q(\delta p),

with :math:`\delta p` the generalised Rodrigues parameters (GRP) of the error
rotation from the reference quaternion :math:`\hat q` (body frame, as in
:mod:`estimators.mekf`), :math:`\beta` the gyro bias (rad/s), and

.. math:: \delta p = \frac{f\,\delta\varrho}{a + \delta w}, \qquad a = 1,\ f = 2(a+1) = 4

(Crassidis & Markley 2003, eqs. 31–32; :func:`dynamics.quaternion.grp_from_quat`),
so that :math:`|\delta p| = 4\tan(\theta/4) \approx \theta`: three unconstrained
components that stay well defined up to a half turn and beyond, where
sigma points tens of degrees apart still map to distinct attitudes.

**Sigma points** (filterpy's :class:`~filterpy.kalman.MerweScaledSigmaPoints`,
:math:`2n + 1 = 13` of them) are drawn on :math:`x` around the current mean
with :math:`\hat q` as the reference, :math:`\delta p = 0` at the mean (the
reset below keeps it there).

**Propagation** (``fx``): each sigma point becomes a quaternion
:math:`q^{(i)} = \hat q \otimes \delta q(\delta p^{(i)})`, is propagated
through the exact kinematics with its *own* bias-corrected rate,
:math:`q^{(i)+} = q^{(i)} \otimes \delta q\bigl((\tilde\omega - \beta^{(i)})\Delta t\bigr)`,
and returns to GRPs about the propagated mean quaternion
:math:`\hat q^{+} = \hat q \otimes \delta q((\tilde\omega - \hat\beta)\Delta t)`:

.. math:: \delta p^{(i)+} = \operatorname{GRP}\bigl((\hat q^{+})^{-1} \otimes q^{(i)+}\bigr),
          \qquad \beta^{(i)+} = \beta^{(i)}

(eqs. 33–36). filterpy's unscented transform recombines them,
:math:`P^- = \sum_i W_c^{(i)} (\chi^{(i)} - \bar x)(\chi^{(i)} - \bar x)^\mathsf{T} + Q`,
with :math:`Q` the exact discrete process noise of the MEKF's linear model
(:func:`estimators.mekf.discrete_error_model`, §6.2.4) at the mean rate.
(USQUE also adds :math:`\bar Q` to :math:`P` before drawing the sigma points;
we keep filterpy's standard form, which makes USQUE and the MEKF the same
filter to first order.)

**Measurement** (``hx``): the star tracker reading :math:`z`, aligned in sign
with :math:`\hat q`, as GRPs about :math:`\hat q`,
:math:`y = \operatorname{GRP}(\hat q^{-1} \otimes z)`, with
:math:`h(x) = \delta p` and :math:`R` the tracker's body-frame covariance
(rad²; GRPs equal the rotation vector to first order).

**Vector measurements**: for a reading :math:`b = A(q)^\mathsf{T} r + v`
(:mod:`sensors.vector`), each sigma point predicts its own
:math:`h(\chi^{(i)}) = A\bigl(\hat q \otimes \delta q(\delta p^{(i)})\bigr)^\mathsf{T} r`
and filterpy's unscented update takes :math:`R = \sigma^2 I_3`; vectors are
applied one at a time (sequential updates), each followed by the reset, and
the sigma points of a second update in one step are drawn anew from the
updated :math:`(x, P)` (filterpy's ``sigma_points``). **Gating**
(``gate_probability``) tests each reading's NIS with the unscented
:math:`S` before its update.

**Reset**: after each update (or, without a reading, before the next
propagation) the mean's :math:`\delta p` moves into the reference,
:math:`\hat q \leftarrow \hat q \otimes \delta q(\delta p)`,
:math:`\delta p \leftarrow 0` (eq. 45), keeping :math:`P`.

.. _usque-imu:

**IMU models** (:mod:`estimators.imu`, the MEKF's; ``gravity_model``,
``magnetometer_model``, ``rest_updates``, ``hard_iron_fit`` as there; the
hard iron's fit corrects the field before the heading reads it): each
model's reading becomes a measurement function of the sigma points, so
that the unscented transform, not a Jacobian, carries it (Crassidis &
Markley 2003, §III):

* gravity's low-passed direction :math:`z`:
  :math:`h(\chi) = A(\hat q \otimes \delta q(\delta p))^\mathsf{T} e_z
  + D(\beta - \bar\beta)`, with :math:`D` the strapdown's drift
  (:func:`estimators.imu.gravity.drift_jacobian`), the MEKF's bias columns;
* the zero-rate update at rest: :math:`h(\chi) = \beta`, linear, so its
  unscented update is the Kalman update exactly;
* the heading: each point's heading error, measured as zero; the gain's
  attitude rows projected on the vertical and its bias rows kept only for a
  validated field, as the MEKF's, so the covariance takes the general
  gain's form :math:`P - K P_{xz}^\mathsf{T} - P_{xz} K^\mathsf{T} + K S K^\mathsf{T}`
  (the only update filterpy's ``update`` cannot make: its gain is the
  optimal one).

The models read the mean attitude :math:`\hat q \otimes \delta q(\delta p)`,
and the strapdown turns by the mean's bias-corrected rate.

Where filterpy could not express a step: none of the filter's arithmetic is
replaced but the heading's projected gain. The class only supplies ``fx``,
``hx`` and ``residual_x``/``residual_z`` (plain differences: all sigma points
share one reference), keeps the reference quaternion beside filterpy's ``x``,
and does the reset; the IMU models' updates on the sigma points are
:class:`SigmaPointImuUpdates`'s, mixed into it.
filterpy 2.0 redraws the sigma points from :math:`(x^-, P^-)` after ``predict``
for the update (1.4.5 reused the propagated ones); both are valid unscented
updates, and the tests run on the version this project resolves.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import (IDENTITY, grp_from_quat, quat_from_grp, quat_from_rotvec,
                                 quat_multiply, relative_rotation, to_body_frame)
from dynamics.validation import InvalidParameterError, axis_standard_deviations, finite_number
from estimators import imu
from estimators.imu import gravity
from estimators.base import (AttitudeAndBiasEstimator, AttitudeEstimator, finite_state,
                             gate_probability_setting, norm_tolerance_setting)
from estimators.imu.updates import UP, ImuUpdates
from estimators.mekf import discrete_error_model
from estimators.settings import (DEFAULT_ATTITUDE_SIGMA_RAD, DEFAULT_BIAS_SIGMA_RADPS,
                                 DEFAULT_DT_S, DEFAULT_GYRO_NOISE, DEFAULT_MEASUREMENT_COVARIANCE)
from estimators.tunable import GRAVITY_DENSITY, HEADING_DENSITY

#: n, the filter's state: the attitude error's GRPs and the gyro bias.
STATE_SIZE = 6
#: Smallest (n + λ)/n: below it the weights, up to n/(n + λ), exceed 1e8 and
#: the rounding of the weighted sums (1e8 × 2.2e-16 relative) grows until the
#: covariance is no longer positive definite (at α = 1e-7 Cholesky fails).
MIN_SPREAD_RATIO = 1e-8
#: (n + λ) and (n + λ) σ² must stay within these: filterpy takes the Cholesky
#: factor of (n + λ) P, which must neither overflow nor underflow.
MAX_SCALED_VARIANCE = 1e300
MIN_SCALED_VARIANCE = 1e-300


def _unit(q: np.ndarray) -> np.ndarray:
    return q / np.sqrt(q @ q)


def _heading(q: np.ndarray, field: np.ndarray) -> float:
    """The heading of a body-frame field seen through ``q`` (rad from north, east positive)."""
    turned = np.empty(3)
    gravity.rotate(q, field, turned)
    return math.atan2(turned[0], turned[1])


def _wrapped(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _scaling(alpha, beta, kappa) -> tuple[float, float, float, float]:
    """The checked scaling parameters and the spread ``n + λ = α² (n + κ)``."""
    alpha = finite_number("alpha", alpha, strictly_positive=True)
    beta = finite_number("beta", beta, minimum=0.0)
    kappa = finite_number("kappa", kappa)
    if STATE_SIZE + kappa <= 0:
        raise InvalidParameterError("kappa", kappa, f"must be > -{STATE_SIZE} so that "
                                    f"n + kappa > 0 (n = {STATE_SIZE})")
    spread = alpha * alpha * (STATE_SIZE + kappa)
    low, high = MIN_SPREAD_RATIO * STATE_SIZE, MAX_SCALED_VARIANCE
    if not low <= spread <= high:
        name, value = ("alpha", alpha) if alpha != 1.0 else ("kappa", kappa)
        raise InvalidParameterError(
            name, value, f"makes n + lambda = alpha^2 (n + kappa) = {spread:.3g} (alpha = "
            f"{alpha:g}, kappa = {kappa:g}, n = {STATE_SIZE}); it must be within {low:g} and "
            f"{high:g}: smaller, the sigma-point weights exceed 1e8 and their rounding breaks "
            "the covariance's positive definiteness; larger, (n + lambda) P overflows")
    return alpha, beta, kappa, spread


def _check_sigma_spread(name: str, value, spread: float) -> None:
    """Each σ > 0 with (n + λ) σ² a normal, finite double: filterpy draws the
    sigma points from the Cholesky factor of (n + λ) P."""
    sigma = axis_standard_deviations(name, value)
    if sigma.min() == 0:
        raise InvalidParameterError(name, value, "must be > 0 on every axis: USQUE's sigma "
                                    "points need a positive definite covariance")
    for scaled in spread * sigma.min() ** 2, spread * sigma.max() ** 2:
        if not MIN_SCALED_VARIANCE <= scaled <= MAX_SCALED_VARIANCE:
            raise InvalidParameterError(
                name, value, f"makes (n + lambda) sigma^2 = {scaled:.3g} (n + lambda = "
                f"{spread:.3g}); it must be within {MIN_SCALED_VARIANCE:g} and "
                f"{MAX_SCALED_VARIANCE:g}: the sigma points come from the Cholesky factor of "
                "(n + lambda) P")


class SigmaPointImuUpdates(ImuUpdates):
    """The IMU models' updates (:mod:`estimators.imu.updates`) made on USQUE's
    sigma points (module docstring, :ref:`IMU models <usque-imu>`): each
    model's reading a measurement function of the points, the reset after
    each. Mixed into :class:`USQUE`, whose ``filter``, ``q_hat``,
    :meth:`~USQUE._hx_vector`, :meth:`~USQUE._fresh_sigma_points`,
    :meth:`~USQUE._gate` and :meth:`~USQUE._reset` these use."""

    @property
    def estimate(self) -> np.ndarray:
        """The attitude the IMU models read: ``q̂ ⊗ δq(δp)`` of the mean."""
        x = self.filter.x
        if not np.any(x[:3]):
            return self.q_hat
        return _unit(quat_multiply(self.q_hat, quat_from_grp(x[:3])))

    def _gravity_update(self, up, variance: float, dof: int) -> None:
        """Gravity's low-passed direction: ``h(χ) = A(q̂ ⊗ δq(δp))ᵀ e_z + D (β − β̄)``."""
        self._imu_update(up, variance * np.eye(3), self._hx_gravity, dof, "accelerometer",
                         drift=self.imu.drift, mean_bias=self.filter.x[3:].copy())

    def _hx_gravity(self, x, drift, mean_bias):
        return self._hx_vector(x, UP) + drift @ (x[3:] - mean_bias)

    def _rest_update(self, rate, variance: float) -> None:
        """The zero-rate update: ``h(χ) = β``, never gated."""
        self._imu_update(np.asarray(rate, dtype=float), variance * np.eye(3), self._hx_bias, 3,
                         "rest", gated=False)

    @staticmethod
    def _hx_bias(x):
        return x[3:]

    def _imu_update(self, z, R, hx, dof: int, sensor: str, gated: bool = True,
                    **hx_args) -> None:
        """filterpy's unscented update with ``hx``, gated as the vector
        readings are, then the reset."""
        self._fresh_sigma_points()
        if not gated or self.gate_probability is None or self._gate(z, hx, R, dof, sensor,
                                                                     **hx_args):
            self.filter.update(z, R=R, hx=hx, **hx_args)
        self._reset()
        self._updated = True

    def _forget_heading(self) -> None:
        """:meth:`ImuUpdates._forget_heading`, and sigma points drawn anew."""
        super()._forget_heading()
        self._updated = True

    def _heading_update(self, psi: float, variance: float, validated: bool, field,
                        reference) -> None:
        """The heading-only update: each sigma point's heading error
        ``h(χ) = ψ + [ψ(χ) − ψ(x̄)]`` (wrapped), measured 0; the attitude gain
        projected on the vertical ``v`` and the bias gain zeroed unless the
        field is validated, so the covariance takes the general gain's form
        ``P − K P_xzᵀ − P_xz Kᵀ + K S Kᵀ``."""
        self._fresh_sigma_points()
        f = self.filter
        mean_heading = _heading(self.estimate, field)
        h = np.array([[psi + _wrapped(_heading(self._sigma_attitude(s), field) - mean_heading)]
                      for s in f.sigmas_f])
        zp = f.Wm @ h
        S = f.Wc @ ((h - zp) ** 2) + variance
        y = -zp
        if self.gate_probability is None or self.accepts(y, S[None], 1, "magnetometer"):
            Pxz = (f.Wc[:, None] * (f.sigmas_f - f.x)).T @ (h - zp)
            K = Pxz / S
            v = to_body_frame(self.estimate, UP)
            K[:3] = np.outer(v, v @ K[:3])
            if not validated:
                K[3:] = 0.0
            f.x = f.x + (K @ y)
            f.P = f.P - K @ Pxz.T - Pxz @ K.T + K @ (S[None] * K.T)
            f.y, f.S, f.K = y, S[None], K
        self._reset()
        self._updated = True

    def _sigma_attitude(self, sigma) -> np.ndarray:
        return _unit(quat_multiply(self.q_hat, quat_from_grp(sigma[:3])))


class USQUE(SigmaPointImuUpdates, AttitudeAndBiasEstimator):
    """Unscented quaternion estimator (Crassidis & Markley 2003) on filterpy's UKF.

    Parameters
    ----------
    dt, initial_attitude, gyro_noise, gyro_bias_random_walk, gyro_scale_density,
    measurement_covariance, initial_bias_radps, initial_attitude_sigma_rad,
    initial_bias_sigma_radps, output, gate_probability, magnetic_norm_tolerance,
    rate_interpolation, gravity_model, magnetometer_model, rest_updates,
    gravity_density, heading_density, rest_density, hard_iron_fit, on_invalid
        As for :class:`~estimators.MultiplicativeEKF` (the IMU models'
        updates made on the sigma points: :ref:`IMU models <usque-imu>` below).
    alpha, beta, kappa : float
        The scaled sigma points' spread, prior-knowledge and secondary
        scaling parameters (Van der Merwe): ``λ = α² (n + κ) − n``.
        The defaults (1, 2, 0) put the points ``√6 σ`` from the mean.
        ``n + λ`` must be within ``6e-8`` and ``1e300`` and every
        ``(n + λ) σ²`` of the initial covariance within ``1e-300`` and
        ``1e300`` (σ > 0 on every axis), so that the Cholesky factor of
        ``(n + λ) P`` exists in floating point.

    The filterpy ``UnscentedKalmanFilter`` is :attr:`filter` (``x`` is
    [δp, β] with δp about :attr:`q_hat`; ``P``, ``sigmas_f``, ``Wm``, ``Wc``,
    ``y``, ``S``, ``K`` as filterpy keeps them).
    """

    name = "usque"
    label = "USQUE (UKF)"
    #: The filters' tunables, and the IMU models' densities (named only).
    tunable = AttitudeAndBiasEstimator.tunable + (GRAVITY_DENSITY, HEADING_DENSITY)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 gyro_noise: float = DEFAULT_GYRO_NOISE, gyro_bias_random_walk: float = 0.0,
                 gyro_scale_density: float = 0.0,
                 measurement_covariance=DEFAULT_MEASUREMENT_COVARIANCE,
                 initial_bias_radps=(0.0, 0.0, 0.0),
                 initial_attitude_sigma_rad=DEFAULT_ATTITUDE_SIGMA_RAD,
                 initial_bias_sigma_radps=DEFAULT_BIAS_SIGMA_RADPS, alpha: float = 1.0,
                 beta: float = 2.0,
                 kappa: float = 0.0, output: str = "posterior",
                 gate_probability: float | None = None,
                 magnetic_norm_tolerance: float | None = None, rate_interpolation: str = "hold",
                 gravity_model: str = "reading", magnetometer_model: str = "vector",
                 rest_updates: bool = False, gravity_density: float = imu.GRAVITY_DENSITY,
                 heading_density: float = imu.HEADING_DENSITY,
                 rest_density: float = imu.REST_DENSITY, hard_iron_fit: bool = False,
                 on_invalid: str = "raise"):
        AttitudeEstimator.__init__(self, dt=dt, initial_attitude=initial_attitude,
                                   on_invalid=on_invalid)
        self._configure_imu(gravity_model=gravity_model, magnetometer_model=magnetometer_model,
                            rest_updates=rest_updates, gravity_density=gravity_density,
                            heading_density=heading_density, rest_density=rest_density,
                            hard_iron_fit=hard_iron_fit)
        self.gate_probability = gate_probability_setting(gate_probability)
        self.magnetic_norm_tolerance = norm_tolerance_setting(magnetic_norm_tolerance)
        alpha, beta, kappa, spread = _scaling(alpha, beta, kappa)
        _check_sigma_spread("initial_attitude_sigma_rad", initial_attitude_sigma_rad, spread)
        _check_sigma_spread("initial_bias_sigma_radps", initial_bias_sigma_radps, spread)
        # Here, not at the top: building a scenario (and --help) needs no filterpy.
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
        points = MerweScaledSigmaPoints(STATE_SIZE, alpha=alpha, beta=beta, kappa=kappa)
        self.filter = UnscentedKalmanFilter(dim_x=STATE_SIZE, dim_z=3, dt=self.dt, hx=self._hx,
                                            fx=self._fx, points=points)
        self._configure(gyro_noise=gyro_noise, gyro_bias_random_walk=gyro_bias_random_walk,
                        gyro_scale_density=gyro_scale_density,
                        measurement_covariance=measurement_covariance,
                        initial_bias_radps=initial_bias_radps,
                        initial_attitude_sigma_rad=initial_attitude_sigma_rad,
                        initial_bias_sigma_radps=initial_bias_sigma_radps, output=output,
                        rate_interpolation=rate_interpolation)
        self.filter.R = self.R
        self.reset()

    def reset(self) -> None:
        self.q_hat = self.initial_attitude.copy()
        self._reset_filter(np.concatenate([np.zeros(3), self.initial_bias_radps]),
                           self.initial_covariance.copy())
        # An update before the first predict needs sigma points about (x₀, P₀),
        # which filterpy only draws in predict.
        self.filter.sigmas_f = self.filter.points_fn.sigma_points(self.filter.x, self.filter.P)
        self._updated = False
        self._restart_rates()
        if self.imu is not None:
            self.imu.reset(self.q_hat)
        self._record()

    def _record(self) -> None:
        """Keep the estimate being output; ``P``'s GRP block is the body-frame
        small-angle covariance to first order (rad²)."""
        x = self.filter.x
        q = self.q_hat if not np.any(x[:3]) else _unit(
            quat_multiply(self.q_hat, quat_from_grp(x[:3])))
        self._output = (q, x[3:].copy(), self.filter.P)

    # The model, as filterpy calls it: fx on each sigma point, hx on each.
    def _fx(self, x, dt, omega_meas_radps, q_reference_next):
        q = quat_multiply(self.q_hat, quat_from_grp(x[:3]))
        q = quat_multiply(q, quat_from_rotvec((omega_meas_radps - x[3:]) * dt))
        error = relative_rotation(q_reference_next, _unit(q))
        return np.concatenate([grp_from_quat(error), x[3:]])

    @staticmethod
    def _hx(x):
        return x[:3]

    def _reset(self) -> None:
        """Fold the mean's δp into the reference quaternion (eq. 45)."""
        x = self.filter.x
        self.q_hat = _unit(quat_multiply(self.q_hat, quat_from_grp(x[:3])))
        self.filter.x = np.concatenate([np.zeros(3), x[3:]])

    #: Without a reading the prior mean's δp moves into q̂ all the same.
    _without_reading = _reset

    def measured_grp(self, star_tracker_quat: np.ndarray) -> np.ndarray:
        """The reading as GRPs about the reference, sign-aligned first."""
        z = np.asarray(star_tracker_quat, dtype=float)
        if self.q_hat @ z < 0:
            z = -z
        return grp_from_quat(relative_rotation(self.q_hat, z))

    def correct(self, star_tracker_quat: np.ndarray) -> None:
        """filterpy's unscented update with one reading, then the reset."""
        self._fresh_sigma_points()
        z = self.measured_grp(star_tracker_quat)
        if self.gate_probability is None or self._gate(z, self._hx, self.R, 3, "star_tracker"):
            self.filter.update(z)
        self._reset()
        self._updated = True

    def correct_vector(self, observation) -> None:
        """filterpy's unscented update with one vector reading, then the reset
        (or the IMU models' updates, where the settings ask)."""
        if self.imu is not None and self._imu_reading(observation):
            # An untrusted field: no update, the reset all the same.
            if np.any(self.filter.x[:3]):
                self._reset()
            self._updated = True
            return
        self._fresh_sigma_points()
        reference = np.asarray(observation.reference, dtype=float)
        R = observation.variance * np.eye(3)
        z = np.asarray(observation.body, dtype=float)
        # A rejected reading, by either test, leaves the reset alone.
        if self.passes_norm(observation) and (
                self.gate_probability is None or self._gate(
                    z, self._hx_vector, R, observation.dof, observation.sensor,
                    reference=reference)):
            self.filter.update(z, R=R, hx=self._hx_vector, reference=reference)
        self._reset()
        self._updated = True

    def _hx_vector(self, x, reference):
        """A sigma point's predicted body vector ``A(q̂ ⊗ δq(δp))ᵀ r``."""
        return to_body_frame(_unit(quat_multiply(self.q_hat, quat_from_grp(x[:3]))), reference)

    def _fresh_sigma_points(self) -> None:
        """Sigma points about the current ``(x, P)`` for a second update within
        one step (those of the predict no longer describe the state)."""
        if self._updated:
            self.filter.sigmas_f = self.filter.points_fn.sigma_points(self.filter.x,
                                                                      self.filter.P)

    def _gate(self, z, hx, R, dof: int, sensor: str, **hx_args) -> bool:
        """The gating test with the unscented innovation covariance (filterpy's
        transform of the sigma points through ``hx``, as its update computes it)."""
        from filterpy.kalman import unscented_transform
        f = self.filter
        sigmas_h = np.atleast_2d([hx(s, **hx_args) for s in f.sigmas_f])
        zp, S = unscented_transform(sigmas_h, f.Wm, f.Wc, R)
        return self.accepts(z - zp, S, dof, sensor)

    def propagate(self, omega_meas_radps: np.ndarray, dt: float | None = None) -> None:
        """Sigma points through the exact kinematics; P⁻ = UT + Q (over ``dt``
        if given: part of a step)."""
        dt = self.dt if dt is None else dt
        self._updated = False
        omega = np.asarray(omega_meas_radps, dtype=float)
        omega_hat = omega - self.filter.x[3:]
        q_next = _unit(quat_multiply(self.q_hat, quat_from_rotvec(omega_hat * dt)))
        _, self.filter.Q = discrete_error_model(omega_hat, dt, self.gyro_noise,
                                                self.gyro_bias_random_walk,
                                                self.gyro_scale_density)
        self.filter.predict(dt=dt, omega_meas_radps=omega, q_reference_next=q_next)
        if self.imu is not None:
            self.imu.propagate(omega_hat * dt, dt)
        # The prior mean's δp stays in x until the next update or reset: the
        # sigma points filterpy drew for the update are relative to q_next.
        self.q_hat = q_next

    def state_is_finite(self) -> bool:
        return finite_state(self.q_hat, self.filter.P) and finite_state(self.filter.x)
