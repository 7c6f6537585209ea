r"""Multiplicative extended Kalman filter (MEKF) with gyro-bias estimation.

The attitude filter spacecraft fly (Lefferts, Markley & Shuster 1982;
Markley & Crassidis 2014, §6.2, "the MEKF"). The *global* state is the unit
quaternion :math:`\hat q` and the gyro bias estimate :math:`\hat\beta`; the
Kalman filter runs on the six-component *error* state

.. math:: \Delta x = \begin{bmatrix}\delta\theta \\ \Delta\beta\end{bmatrix}, \qquad
          q = \hat q \otimes \delta q(\delta\theta), \qquad
          \beta = \hat\beta + \Delta\beta,

with :math:`\delta\theta` (rad) the small rotation from the estimated to the
true body frame, expressed in the body frame, and :math:`\delta q` the
exponential map (:func:`dynamics.quaternion.quat_from_rotvec`). The book
writes :math:`q = \delta q \otimes \hat q` in its own product and
attitude-matrix convention; in this toolkit's Hamilton, body-to-reference
convention the same body-frame error multiplies on the right, and the
equations below are unchanged.

**Gyro model** (:mod:`sensors.gyro`): :math:`\tilde\omega = \omega + \beta +
\eta_v`, :math:`\dot\beta = \eta_u`, with densities :math:`\sigma_v` (angle
random walk, rad/√s; :math:`\sigma_v^2` is the workshop's noise power) and
:math:`\sigma_u` (bias rate random walk, rad/s^{3/2}).

**Propagation** over a step :math:`\Delta t` with the bias-corrected rate
:math:`\hat\omega = \tilde\omega_k - \hat\beta` held constant (§6.2.4,
eqs. 6.60 and 6.83–6.85; Crassidis & Markley 2003, eqs. 43–46):

.. math::

    \hat q_{k+1} = \hat q_k \otimes \delta q(\hat\omega\,\Delta t), \qquad
    \hat\beta_{k+1} = \hat\beta_k, \qquad
    P_{k+1} = \Phi_k P_k \Phi_k^\mathsf{T} + Q_k,

the quaternion integrated exactly for a constant rate. With
:math:`W = [\hat\omega\times]`, :math:`w = |\hat\omega|` and
:math:`x = w\Delta t`, the error state's exact discrete transition is

.. math::

    \Phi = \begin{bmatrix}\Phi_{11} & \Phi_{12}\\ 0 & I_3\end{bmatrix},\quad
    \Phi_{11} = I_3 - \frac{\sin x}{w} W + \frac{1 - \cos x}{w^2} W^2,\quad
    \Phi_{12} = -\Bigl(I_3\Delta t - \frac{1-\cos x}{w^2} W
                + \frac{x - \sin x}{w^3} W^2\Bigr),

and the exact discrete process noise :math:`Q = \int_0^{\Delta t}\Phi(s) G
\operatorname{diag}(\sigma_v^2 I_3, \sigma_u^2 I_3) G^\mathsf{T}\Phi(s)^\mathsf{T} ds`
is

.. math::

    Q_{11} &= \sigma_v^2\Delta t\, I_3 + \sigma_u^2\Bigl(\frac{\Delta t^3}{3} I_3
             + \frac{x^3/3 + 2\sin x - 2x}{w^5} W^2\Bigr), \\
    Q_{12} &= Q_{21}^\mathsf{T} = -\sigma_u^2\Bigl(\frac{\Delta t^2}{2} I_3
             - \frac{x - \sin x}{w^3} W + \frac{x^2/2 + \cos x - 1}{w^4} W^2\Bigr), \\
    Q_{22} &= \sigma_u^2 \Delta t\, I_3.

Below :math:`x = 0.1` the five coefficients come from their Taylor series
(:func:`transition_coefficients`), where the closed forms lose digits.

**The rate's own error** (``gyro_scale_density``, 0 by default: the book's
gyro model). A real gyro also errs in proportion to the rate it reads: its
scale factors and its axes' misalignment (which calibration filters estimate
as states: Pittelkau, "Kalman filtering for spacecraft system alignment
calibration", *JGCD* 24(6), 2001), and the timing of its samples. The part
along the rate (a scale error common to the axes, the timing) is modelled
here; what errs across it (the axes' own scale errors, misalignment) is
left to :math:`\sigma_v`. Where these are not estimated, the filter takes them
as a white relative error of the rate, :math:`\tilde\omega = (1 + \nu_s)\,
\omega + \beta + \eta_v` with :math:`\nu_s` of density :math:`S_s` (s):
noise along the rate, which :math:`\Phi_{11}` (a turn about
:math:`\hat\omega`) leaves as it is, so its exact share of :math:`Q` is

.. math:: Q_{11} \mathrel{+}= S_s\, \Delta t\; \hat\omega\,\hat\omega^\mathsf{T}.

In a fast turn the heading then drifts as much as the filter believes it
may, and the field corrects it sooner; at rest it adds nothing. An IMU
recording's filters take :data:`estimators.imu.GYRO_SCALE_DENSITY`.

**Measurement** (§6.2.2): the star tracker reading :math:`z` (a quaternion)
is first aligned in sign with the prediction (:math:`z \leftarrow -z` if
:math:`\hat q \cdot z < 0`: :math:`q` and :math:`-q` are one attitude, and
real trackers flip), then turned into the measured small angle

.. math:: y = \log\bigl(\hat q^{-1} \otimes z\bigr) = \delta\theta + v, \qquad
          H = [\,I_3\ \ 0_3\,], \qquad v \sim \mathcal N(0, R),

with :math:`\log` the rotation vector (:func:`dynamics.quaternion.rotvec_from_quat`)
and :math:`R` (3x3, rad²) the tracker's body-frame error covariance.

**Update** (filterpy's :class:`~filterpy.kalman.KalmanFilter`, Joseph form):
:math:`K = P H^\mathsf{T}(H P H^\mathsf{T} + R)^{-1}`,
:math:`\Delta x^+ = K y` (the prior error state is zero),
:math:`P^+ = (I - KH) P (I - KH)^\mathsf{T} + K R K^\mathsf{T}`.

**Reset** (§6.2.3): the estimated error moves into the global state and the
error state returns to zero,

.. math:: \hat q^+ = \frac{\hat q \otimes \delta q(\delta\theta^+)}
          {\lVert \hat q \otimes \delta q(\delta\theta^+) \rVert}, \qquad
          \hat\beta^+ = \hat\beta + \Delta\beta^+, \qquad \Delta x = 0,

keeping :math:`P^+` (the reset's effect on the covariance is second order).

Why filterpy's linear :class:`~filterpy.kalman.KalmanFilter` and not its
``ExtendedKalmanFilter``: the error state is linear in the MEKF — its
transition :math:`\Phi` and measurement matrix :math:`H` are matrices, and
all the nonlinearity lives in the global state, which the filter's ``x``
never holds. The class passes :math:`\Phi_k` and :math:`Q_k` to
``predict`` each step, lets filterpy's ``update`` do the Joseph-form
correction, and does the reset itself; ``x`` (the error state, 1-D ``(6,)``),
``P``, ``y``, ``S``, ``K``, ``x_prior``/``P_prior`` and ``x_post``/``P_post``
are filterpy's, there to inspect.

**Vector measurements** (§6.2.2; Lefferts, Markley & Shuster 1982): a
vector sensor measures :math:`b = A(q)^\mathsf{T} r + v`,
:math:`v \sim \mathcal N(0, \sigma^2 I_3)` (:mod:`sensors.vector`). With
:math:`A(q) = A(\hat q)(I_3 + [\delta\theta\times])` to first order,

.. math:: \hat b = A(\hat q)^\mathsf{T} r, \qquad
          y = b - \hat b = [\hat b\times]\,\delta\theta + v, \qquad
          H = \bigl[\,[\hat b\times]\ \ 0_3\,\bigr], \qquad R = \sigma^2 I_3,

applied one vector at a time (sequential updates, each followed by its
reset, so the next vector's :math:`\hat b` comes from the updated
:math:`\hat q`), after the star tracker's reading of the same step.

**Magnetometer bias states** (``magnetometer_bias_states``): a spacecraft's
magnetometer reads its own hard iron :math:`b_m` (the field of its
electronics, in its own axes) beside the field, :math:`b = A^\mathsf{T} r +
b_m + v`. The error state grows by three, :math:`\Delta b_m` (the reading's
unit), constant (:math:`\Phi` and :math:`Q` are the identity and zero in its
block), and a magnetometer reading's model is

.. math:: \hat b = A(\hat q)^\mathsf{T} r + \hat b_m, \qquad
          H = \bigl[\,[A(\hat q)^\mathsf{T} r\times]\ \ 0_3\ \ I_3\,\bigr],

the reset adding :math:`\Delta b_m^+` to :math:`\hat b_m` (the state
augmentation of Lefferts, Markley & Shuster 1982 and M&C 2014, §6.2; the
filter form of the attitude-independent calibration of Crassidis, Lai &
Harman 2005). The field's turning along an orbit makes the hard iron
observable apart from the attitude. Its prior is
``initial_magnetometer_bias_sigma`` per axis; a scenario that declares a
hard iron (``[magnetometer] bias_nT``) turns the states on with a prior of at
least its size on each axis. Their settings and bookkeeping are
:class:`~estimators.magnetometer_bias.MagnetometerBiasStates`'s, mixed into the
class; the update, the reset and the propagation here carry the states.

**Gating** (``gate_probability``): each reading's NIS
:math:`y^\mathsf{T} S^{-1} y`, :math:`S = H P H^\mathsf{T} + R`, is tested
against its χ² quantile before the update
(:meth:`~estimators.gating.InnovationGate.accepts`); a reading that fails is
counted and not applied.

Order within step ``k``: correct with the reading :math:`z_k` if there is
one, output the corrected :math:`\hat q_{k|k}` (``output="posterior"``, the
default; ``"prior"`` outputs :math:`\hat q_{k|k-1}` as the workshop EKF
does), then propagate to :math:`k+1` with :math:`\tilde\omega_k`, the gyro's
average rate over that step.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import (IDENTITY, quat_from_rotvec, quat_multiply, relative_rotation,
                                 rotvec_from_quat, skew, to_body_frame)
from estimators import imu
from estimators.base import (AttitudeAndBiasEstimator, AttitudeEstimator, finite_state,
                             gate_probability_setting, norm_tolerance_setting)
from estimators.imu.updates import ErrorStateUpdates
from estimators.magnetometer_bias import (CORE_STATES, MAGNETOMETER_BIAS_SIGMA,
                                          MagnetometerBiasStates, estimates_hard_iron)
from estimators.settings import (DEFAULT_ATTITUDE_SIGMA_RAD, DEFAULT_BIAS_SIGMA_RADPS,
                                 DEFAULT_DT_S, DEFAULT_GYRO_NOISE, DEFAULT_MEASUREMENT_COVARIANCE)
from estimators.tunable import GRAVITY_DENSITY, HEADING_DENSITY

#: The names other modules import from here, wherever each is defined (the
#: hard-iron states' settings and bookkeeping are :mod:`estimators.magnetometer_bias`'s).
__all__ = ["MultiplicativeEKF", "discrete_error_model", "transition_coefficients",
           "SERIES_BELOW", "CORE_STATES", "MAGNETOMETER_BIAS_SIGMA", "estimates_hard_iron"]

_I3 = np.eye(3)
#: Below this rotation per step, x = |ω̂|Δt, the transition's coefficients use
#: their Taylor series: the closed form of (x³/3 + 2 sin x − 2x)/w⁵ cancels
#: to relative error ~60 ε/x⁴ (1e-10 at 0.1), the series' first omitted term is
#: below 1e-14 relative there.
SERIES_BELOW = 0.1


def transition_coefficients(rate_norm_radps: float, dt: float) -> tuple[float, ...]:
    r"""The five scalar coefficients of :math:`\Phi` and :math:`Q`, for :math:`w = |\hat\omega|`:

    ``(sin x / w, (1 - cos x)/w², (x - sin x)/w³, (x³/3 + 2 sin x - 2x)/w⁵,
    (x²/2 + cos x - 1)/w⁴)`` with ``x = w Δt``; their Taylor series below
    :data:`SERIES_BELOW`.
    """
    x = rate_norm_radps * dt
    if x < SERIES_BELOW:
        return series_coefficients(x, dt)
    return trigonometric_coefficients(rate_norm_radps, x)


def series_coefficients(x: float, dt: float) -> tuple[float, ...]:
    """:func:`transition_coefficients` by their Taylor series in ``x = w Δt``."""
    x2 = x * x
    dt2 = dt * dt
    return (dt * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0))),
            dt2 * (0.5 - x2 / 24.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0))),
            dt2 * dt * (1.0 / 6.0 - x2 / 120.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0))),
            dt2 * dt2 * dt * (1.0 / 60.0 - x2 / 2520.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0))),
            dt2 * dt2 * (1.0 / 24.0 - x2 / 720.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0))))


def trigonometric_coefficients(w: float, x: float) -> tuple[float, ...]:
    """:func:`transition_coefficients` from sin x and cos x (``x = w Δt``)."""
    s, c = math.sin(x), math.cos(x)
    w2 = w * w
    return (s / w, (1.0 - c) / w2, (x - s) / (w2 * w), (x * x * x / 3.0 + 2.0 * s - 2.0 * x)
            / (w2 * w2 * w), (0.5 * x * x + c - 1.0) / (w2 * w2))


def discrete_error_model(omega_hat_radps: np.ndarray, dt: float, gyro_noise: float,
                         gyro_bias_random_walk: float, gyro_scale_density: float = 0.0
                         ) -> tuple[np.ndarray, np.ndarray]:
    r"""The error state's exact transition :math:`\Phi` and process noise :math:`Q` (6x6).

    Parameters
    ----------
    omega_hat_radps : (3,) bias-corrected rate :math:`\hat\omega`, rad/s
    dt : step, s
    gyro_noise : :math:`\sigma_v^2`, rad²/s
    gyro_bias_random_walk : :math:`\sigma_u`, rad/s^{3/2}
    gyro_scale_density : :math:`S_s`, s (the rate's own error, module docstring)
    """
    w = float(np.sqrt(omega_hat_radps @ omega_hat_radps))
    s1, c2, s3, q5, q4 = transition_coefficients(w, dt)
    W = skew(omega_hat_radps)
    W2 = W @ W
    phi = np.eye(6)
    phi[:3, :3] = _I3 - s1 * W + c2 * W2
    phi[:3, 3:] = -(dt * _I3 - c2 * W + s3 * W2)
    su2 = gyro_bias_random_walk * gyro_bias_random_walk
    q = np.empty((6, 6))
    q[:3, :3] = gyro_noise * dt * _I3 + su2 * (dt ** 3 / 3.0 * _I3 + q5 * W2)
    if gyro_scale_density > 0.0:
        q[:3, :3] += gyro_scale_density * dt * np.outer(omega_hat_radps, omega_hat_radps)
    q[:3, 3:] = -su2 * (0.5 * dt * dt * _I3 - s3 * W + q4 * W2)
    q[3:, :3] = q[:3, 3:].T
    q[3:, 3:] = su2 * dt * _I3
    return phi, q


def _with_constant_states(phi: np.ndarray, q: np.ndarray, size: int) -> tuple:
    """``Φ`` and ``Q`` grown to ``size`` states by constant ones (identity, no noise)."""
    grown_phi, grown_q = np.eye(size), np.zeros((size, size))
    n = len(phi)
    grown_phi[:n, :n], grown_q[:n, :n] = phi, q
    return grown_phi, grown_q


class MultiplicativeEKF(ErrorStateUpdates, MagnetometerBiasStates, AttitudeAndBiasEstimator):
    """The MEKF: attitude and gyro bias, six error states, on filterpy's ``KalmanFilter``.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,) array-like
        :math:`\\hat q_0`, scalar-first; normalised.
    gyro_noise, gyro_bias_random_walk, gyro_scale_density : float
        The gyro model the filter assumes: :math:`\\sigma_v^2` in rad²/s (the
        gyro's noise power), :math:`\\sigma_u` in rad/s^{3/2}, and :math:`S_s`
        in s, the rate's own relative error (module docstring; 0: none).
    measurement_covariance : float, (3,) or (3, 3)
        :math:`R` in rad², the star tracker's body-frame error covariance.
    initial_bias_radps : (3,) array-like
        :math:`\\hat\\beta_0`, rad/s.
    initial_attitude_sigma_rad : float or (3,)
        Standard deviation of the initial attitude error per axis, rad.
    initial_bias_sigma_radps : float or (3,)
        Standard deviation of the initial bias error per axis, rad/s.
    output : {"posterior", "prior"}
        Which estimate :meth:`step` returns.
    gate_probability : float or None
        Innovation gating: a reading whose NIS exceeds the χ² quantile of
        this probability is rejected (None: no gating).
    magnetic_norm_tolerance : float or None
        Magnetic disturbance detection: a magnetometer reading whose
        magnitude is off its reference's by more than this fraction is
        rejected (None: no test; :meth:`~estimators.gating.InnovationGate.passes_norm`).
    rate_interpolation : {"hold", "trapezoid", "end"}
        The rate over a step (:mod:`estimators.sampled_rate`): its reading
        held (an averaging gyro's), the mean of the readings at its two ends
        (a sampled gyro's), or the reading at its end (an IMU's, whose
        reading is the rate over the interval before it).
    gravity_model : {"reading", "lowpass"}
        The accelerometer as a gravity reading of its own variance, or
        gravity low-passed in the strapdown frame (:mod:`estimators.imu.gravity`).
    magnetometer_model : {"vector", "heading"}
        The magnetometer as a field vector reading, or as a heading
        reference only (:mod:`estimators.imu.heading`).
    rest_updates : bool
        Detect rest and apply the zero-rate update of the bias
        (:mod:`estimators.imu.rest`).
    gravity_density, heading_density, rest_density : float
        The densities of the IMU models' errors: gravity's low-passed
        direction (rad²·s), the heading (rad²·s), the low-passed rate at rest
        (rad²/s²·s); a reading's variance is the density over the time since
        the sensor's last reading.
    hard_iron_fit : bool
        Fit the magnetometer's hard iron online from its readings alone and
        take it off each reading before the heading model reads it
        (:mod:`estimators.imu.hard_iron`; needs ``magnetometer_model="heading"``).
    magnetometer_bias_states : bool
        Estimate the magnetometer's hard iron as three more error states
        (module docstring; needs ``magnetometer_model="vector"``).
    initial_magnetometer_bias_sigma : float or (3,)
        Standard deviation of the initial hard-iron error per axis, in the
        magnetometer readings' unit (nT in a scenario).
    on_invalid : {"raise", "skip"}
        What to do with an unusable measurement (see
        :meth:`~estimators.AttitudeEstimator.step`). Readings are always
        aligned in sign with the prediction (the innovation is a rotation).

    The filterpy ``KalmanFilter`` on the error state is :attr:`filter`
    (``x`` is the error δθ, δβ and, if estimated, δb_m, zero after each
    reset; ``P``, ``y``, ``S``, ``K`` as filterpy keeps them); :attr:`q_hat`,
    :attr:`beta_hat` and :attr:`magnetometer_bias` are the global estimates.
    """

    name = "mekf"
    label = "MEKF"
    #: The filters' tunables, and the IMU models' densities (named only).
    tunable = AttitudeAndBiasEstimator.tunable + (GRAVITY_DENSITY, HEADING_DENSITY)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 gyro_noise: float = DEFAULT_GYRO_NOISE, gyro_bias_random_walk: float = 0.0,
                 measurement_covariance=DEFAULT_MEASUREMENT_COVARIANCE,
                 initial_bias_radps=(0.0, 0.0, 0.0), gyro_scale_density: float = 0.0,
                 initial_attitude_sigma_rad=DEFAULT_ATTITUDE_SIGMA_RAD,
                 initial_bias_sigma_radps=DEFAULT_BIAS_SIGMA_RADPS, output: str = "posterior",
                 gate_probability: float | None = None,
                 magnetic_norm_tolerance: float | None = None, rate_interpolation: str = "hold",
                 gravity_model: str = "reading", magnetometer_model: str = "vector",
                 rest_updates: bool = False, gravity_density: float = imu.GRAVITY_DENSITY,
                 heading_density: float = imu.HEADING_DENSITY,
                 rest_density: float = imu.REST_DENSITY, hard_iron_fit: bool = False,
                 magnetometer_bias_states: bool = False,
                 initial_magnetometer_bias_sigma=MAGNETOMETER_BIAS_SIGMA,
                 on_invalid: str = "raise"):
        AttitudeEstimator.__init__(self, dt=dt, initial_attitude=initial_attitude,
                                   on_invalid=on_invalid)
        self._configure_imu(gravity_model=gravity_model, magnetometer_model=magnetometer_model,
                            rest_updates=rest_updates, gravity_density=gravity_density,
                            heading_density=heading_density, rest_density=rest_density,
                            hard_iron_fit=hard_iron_fit)
        self.gate_probability = gate_probability_setting(gate_probability)
        self.magnetic_norm_tolerance = norm_tolerance_setting(magnetic_norm_tolerance)
        self._configure(gyro_noise=gyro_noise, gyro_bias_random_walk=gyro_bias_random_walk,
                        gyro_scale_density=gyro_scale_density,
                        measurement_covariance=measurement_covariance,
                        initial_bias_radps=initial_bias_radps,
                        initial_attitude_sigma_rad=initial_attitude_sigma_rad,
                        initial_bias_sigma_radps=initial_bias_sigma_radps, output=output,
                        rate_interpolation=rate_interpolation)
        self._configure_magnetometer_bias(magnetometer_bias_states,
                                          initial_magnetometer_bias_sigma)
        # Here, not at the top: building a scenario (and --help) needs no filterpy.
        from filterpy.kalman import KalmanFilter
        self.filter = KalmanFilter(dim_x=self.state_size, dim_z=3)
        self.filter.R = self.R
        self.filter.H = np.hstack([_I3, np.zeros((3, self.state_size - 3))])
        self.reset()

    def reset(self) -> None:
        self.q_hat = self.initial_attitude.copy()
        self.beta_hat = self.initial_bias_radps.copy()
        #: The hard-iron estimate (zero, and kept so, without its states).
        self.magnetometer_bias = np.zeros(3)
        self._reset_filter(np.zeros(self.state_size), self.initial_covariance.copy())
        self._restart_rates()
        if self.imu is not None:
            self.imu.reset(self.q_hat)
        self._record()

    def _record(self) -> None:
        """Keep the estimate being output and its covariance (new arrays each step)."""
        self._output = (self.q_hat, self.beta_hat, self.filter.P)

    def innovation(self, star_tracker_quat: np.ndarray) -> np.ndarray:
        """The measured small angle ``y = log(q̂⁻¹ ⊗ z)`` (rad), ``z`` sign-aligned first."""
        z = np.asarray(star_tracker_quat, dtype=float)
        if self.q_hat @ z < 0:
            z = -z
        return rotvec_from_quat(relative_rotation(self.q_hat, z))

    def correct(self, star_tracker_quat: np.ndarray) -> None:
        """Kalman update with one reading, then the reset."""
        y = self.innovation(star_tracker_quat)
        if self.gate_probability is not None and not self.accepts(
                y, self.filter.P[:3, :3] + self.R, 3, "star_tracker"):
            return
        self.filter.update(y)
        self._reset()

    def vector_model(self, observation) -> tuple[np.ndarray, np.ndarray]:
        """``(y, H)``: the innovation ``b − A(q̂)ᵀ r`` of a vector reading and
        its error-state Jacobian ``[[b̂×] 0]`` (module docstring); a
        magnetometer's with its hard-iron states, ``b − A(q̂)ᵀ r − b̂_m`` and
        ``[[b̂×] 0 I]``."""
        predicted = to_body_frame(self.q_hat, np.asarray(observation.reference, dtype=float))
        H = np.zeros((3, self.state_size))
        H[:, :3] = skew(predicted)
        if self._reads_hard_iron(observation):
            H[:, CORE_STATES:] = _I3
            predicted = predicted + self.magnetometer_bias
        return np.asarray(observation.body, dtype=float) - predicted, H

    def correct_vector(self, observation) -> None:
        """Kalman update with one vector reading, then the reset (or the IMU
        models' updates, where the settings ask: :mod:`estimators.imu.updates`).
        A magnetometer's norm test reads the field less the hard-iron estimate."""
        tested = self._less_hard_iron(observation)
        if self._imu_reading(observation) or not self.passes_norm(tested):
            return
        y, H = self.vector_model(observation)
        R = observation.variance * _I3
        if self.gate_probability is not None and not self.accepts(
                y, H @ self.filter.P @ H.T + R, observation.dof, observation.sensor):
            return
        self.filter.update(y, R=R, H=H)
        self._reset()

    def _reset(self) -> None:
        """Move the error state into the global state (§6.2.3)."""
        delta_theta, delta_beta = self.filter.x[:3], self.filter.x[3:CORE_STATES]
        q = quat_multiply(self.q_hat, quat_from_rotvec(delta_theta))
        self.q_hat = q / np.sqrt(q @ q)
        self.beta_hat = self.beta_hat + delta_beta
        if self.magnetometer_bias_states:
            self.magnetometer_bias = self.magnetometer_bias + self.filter.x[CORE_STATES:]
        self.filter.x = np.zeros(self.state_size)

    def propagate(self, omega_meas_radps: np.ndarray, dt: float | None = None) -> None:
        """Global state and covariance from ``k`` to ``k + 1`` with the gyro's
        step average (over ``dt`` if given: part of a step)."""
        dt = self.dt if dt is None else dt
        omega_hat = np.asarray(omega_meas_radps, dtype=float) - self.beta_hat
        phi, q = discrete_error_model(omega_hat, dt, self.gyro_noise,
                                      self.gyro_bias_random_walk, self.gyro_scale_density)
        if self.magnetometer_bias_states:             # a constant hard iron: Φ = I, Q = 0
            phi, q = _with_constant_states(phi, q, self.state_size)
        self.filter.predict(F=phi, Q=q)
        propagated = quat_multiply(self.q_hat, quat_from_rotvec(omega_hat * dt))
        self.q_hat = propagated / np.sqrt(propagated @ propagated)
        if self.imu is not None:
            self.imu.propagate(omega_hat * dt, dt)

    def state_is_finite(self) -> bool:
        return finite_state(self.q_hat, self.filter.P) and finite_state(self.beta_hat)
