"""The filter under the workshop's EKF (:mod:`estimators.ekf`): filterpy's
``ExtendedKalmanFilter`` with the workshop's nonlinear model as its
prediction. Apart from the estimator so that importing the estimator (to
build a scenario, or to answer ``--help``) does not import filterpy."""
from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from estimators.model import propagate_with_jacobian


class WorkshopModelEKF(ExtendedKalmanFilter):
    """filterpy's ``ExtendedKalmanFilter`` (``dim_x = dim_z = 4``) whose
    ``predict_x`` takes the state through the workshop's nonlinear ``f`` with
    the gyro rate ``u`` (rad/s) and sets ``F`` to the exact Jacobian at the
    pre-step ``x`` (:func:`estimators.model.propagate_with_jacobian`)."""

    def __init__(self, dt: float):
        super().__init__(dim_x=4, dim_z=4)
        self.dt = dt

    def predict_x(self, u=np.zeros(3)) -> None:
        self.x, self.F = propagate_with_jacobian(self.x, np.asarray(u, float), self.dt)
