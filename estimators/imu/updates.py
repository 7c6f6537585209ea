r"""The IMU models' measurement updates of a six-state attitude and bias
filter, each as its model's docstring gives it, in the error state
:math:`[\delta\theta, \Delta\beta]`:

* gravity's low-passed direction (:mod:`estimators.imu.gravity`):
  :math:`y = z - A(\hat q)^\mathsf{T} e_z`, :math:`H = [[A^\mathsf{T}e_z\times]\ D]`
  (:math:`D` the strapdown's drift, :func:`estimators.imu.gravity.drift_jacobian`),
  :math:`R = S_g / T\, I_3`;
* the zero-rate update at rest (:mod:`estimators.imu.rest`):
  :math:`y = \bar\omega - \hat\beta`, :math:`H = [0\ I_3]`, :math:`R = S_r/T\, I_3`;
* the heading (:mod:`estimators.imu.heading`): :math:`y = \psi`,
  :math:`H = [v^\mathsf{T}\ 0]`, the attitude gain projected on :math:`v`,
  the bias rows kept only where the field is validated.

:class:`ImuUpdates` reads the sensors through the models and decides which
update applies; each filter makes the update its own way:

* the MEKF (:class:`ErrorStateUpdates`): the Kalman update of the error
  state in Joseph form (Markley & Crassidis 2014, §6.2), then its reset;
* USQUE (:class:`estimators.usque.USQUE`): the same models as measurement
  functions of its sigma points (Crassidis & Markley 2003; the unscented
  transform of a model linear in the state is that model's Kalman update).
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import skew, to_body_frame
from dynamics.validation import InvalidParameterError, boolean, finite_number, one_of
from estimators.imu import GRAVITY_MODELS, MAGNETOMETER_MODELS, ImuModels, gravity, heading

UP = np.array([0.0, 0.0, 1.0])


class ImuUpdates:
    """What a six-state filter with :attr:`imu` (an
    :class:`~estimators.imu.ImuModels`, or None) does with an IMU's
    accelerometer and magnetometer readings where its settings ask. The
    filter supplies :meth:`_gravity_update`, :meth:`_rest_update`,
    :meth:`_heading_update` and :attr:`estimate` (the attitude the models
    read)."""

    imu: ImuModels | None = None
    gravity_model = "reading"
    magnetometer_model = "vector"
    rest_updates = False
    hard_iron_fit = False

    def _configure_imu(self, *, gravity_model, magnetometer_model, rest_updates,
                       gravity_density, heading_density, rest_density,
                       hard_iron_fit=False) -> None:
        """Validate and keep the IMU models' settings; the models' state
        (:attr:`imu`) where any is on."""
        self.gravity_model = one_of("gravity_model", gravity_model, GRAVITY_MODELS)
        self.magnetometer_model = one_of("magnetometer_model", magnetometer_model,
                                         MAGNETOMETER_MODELS)
        self.rest_updates = boolean("rest_updates", rest_updates)
        self.hard_iron_fit = boolean("hard_iron_fit", hard_iron_fit)
        if self.hard_iron_fit and self.magnetometer_model != "heading":
            raise InvalidParameterError(
                "hard_iron_fit", True, "needs magnetometer_model = 'heading' (the fit corrects "
                f"the heading model's field): with '{self.magnetometer_model}', set it false")
        for name, value in (("gravity_density", gravity_density),
                            ("heading_density", heading_density),
                            ("rest_density", rest_density)):
            setattr(self, name, finite_number(name, value, strictly_positive=True))
        self.imu = ImuModels(self.dt) if imu_models_on(vars(self)) else None

    def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()):
        if self.imu is not None:
            self.imu.gyro_reading(omega_meas_radps)
        return super()._step(omega_meas_radps, star_tracker_quat, vectors)

    def _step_at(self, omega_meas_radps, star_tracker_quat, offset_s, vectors=()):
        if self.imu is not None:
            self.imu.gyro_reading(omega_meas_radps)
        return super()._step_at(omega_meas_radps, star_tracker_quat, offset_s, vectors)

    def _imu_reading(self, observation) -> bool:
        """Apply ``observation`` through the IMU models; False if they do not
        take it (the filter's own vector update then applies it)."""
        if self.imu is None:
            return False
        if observation.sensor == "accelerometer":
            return self._accelerometer(observation)
        if observation.sensor == "magnetometer" and self.magnetometer_model == "heading":
            self._heading(observation)
            return True
        return False

    def _accelerometer(self, observation) -> bool:
        """Gravity's low-passed direction and, at rest, the zero-rate update;
        False where the reading itself is to be applied as a vector reading."""
        up = np.empty(3)
        interval = self.imu.gravity_reading(np.asarray(observation.body, dtype=float), up)
        used = self.gravity_model == "lowpass"
        if used:
            self._gravity_update(up, gravity.reading_variance(
                self.gravity_density, interval, self.imu.gravity_filter,
                gravity.LOWPASS_TIME_CONSTANT_S), observation.dof)
        if self.rest_updates and self.imu.at_rest:
            self._rest_update(self.imu.rate_lp, self.rest_density / interval)
        return used

    def _heading(self, observation) -> None:
        """The heading-only update, as far as the field is trusted."""
        field = np.asarray(observation.body, dtype=float)
        if self.hard_iron_fit:
            field = self.imu.calibrated_field(field)
        reference = np.asarray(observation.reference, dtype=float)
        psi, interval, trust, validated, forget = self.imu.field_reading(
            self.estimate, field, reference, getattr(observation, "reference_known", True))
        if forget:
            self._forget_heading()
        if trust == 0.0:
            self._reject("magnetometer")
            return
        self._heading_update(psi, trust * trust * self.heading_density / interval, validated,
                             field, reference)

    def _forget_heading(self) -> None:
        """The heading's variance raised along the vertical of :attr:`estimate`
        (:func:`estimators.imu.heading.widen_heading`; for USQUE's GRPs, the
        rotation angle to first order)."""
        heading.widen_heading(to_body_frame(self.estimate, UP), self.filter.P)


def imu_models_on(settings) -> bool:
    """Whether ``settings`` (a filter's constructor keywords, or its
    attributes) turn any IMU model on: a gravity model other than the plain
    reading, the heading-only field, or the rest updates."""
    return (settings.get("gravity_model", "reading") != "reading"
            or settings.get("magnetometer_model", "vector") != "vector"
            or bool(settings.get("rest_updates", False)))


class ErrorStateUpdates(ImuUpdates):
    """The IMU models' updates of the MEKF's error state (module docstring)."""

    @property
    def estimate(self) -> np.ndarray:
        return self.q_hat

    def _gravity_update(self, up, variance: float, dof: int) -> None:
        predicted = to_body_frame(self.q_hat, UP)
        H = np.zeros((3, self.state_size))
        H[:, :3] = skew(predicted)
        H[:, 3:6] = self.imu.drift
        self._error_update(up - predicted, H, variance * np.eye(3), dof, "accelerometer")

    def _rest_update(self, rate, variance: float) -> None:
        H = np.zeros((3, self.state_size))
        H[:, 3:6] = np.eye(3)
        self._error_update(rate - self.beta_hat, H, variance * np.eye(3), 3, "rest",
                           gated=False)

    def _heading_update(self, psi: float, variance: float, validated: bool, field,
                        reference) -> None:
        v = to_body_frame(self.q_hat, UP)
        H = np.zeros((1, self.state_size))
        H[0, :3] = v
        self._error_update(np.array([psi]), H, np.array([[variance]]), 1, "magnetometer",
                           heading_axis=v, bias=validated)

    def _error_update(self, y, H, R, dof: int, sensor: str, heading_axis=None,
                      bias: bool = True, gated: bool = True) -> None:
        """The Kalman update in Joseph form with gain ``K = P Hᵀ S⁻¹``, gated
        if the filter gates (the zero-rate update never is: rest is its own
        test); for the heading, the attitude rows of ``K`` projected on
        ``heading_axis`` and its bias rows zeroed unless ``bias``."""
        f = self.filter
        S = H @ f.P @ H.T + R
        if gated and self.gate_probability is not None and not self.accepts(y, S, dof, sensor):
            return
        K = f.P @ H.T @ np.linalg.inv(S)
        if heading_axis is not None:
            K[:3] = np.outer(heading_axis, heading_axis @ K[:3])
            if not bias:
                K[3:] = 0.0
        I_KH = np.eye(self.state_size) - K @ H
        f.x = K @ y
        f.P = I_KH @ f.P @ I_KH.T + K @ R @ K.T
        f.y, f.S, f.K = y, S, K
        f.x_post, f.P_post = f.x.copy(), f.P.copy()
        self._reset()
