"""What we infer: attitude estimators sharing one interface.

=============================  ==========================================
name                           class
=============================  ==========================================
``dead-reckoning``             :class:`DeadReckoning`
``dead-reckoning-resets``      :class:`DeadReckoningWithResets`
``ekf``                        :class:`QuaternionEKF` (filterpy EKF)
``mekf``                       :class:`MultiplicativeEKF` (filterpy KF)
``usque``                      :class:`USQUE` (filterpy UKF)
=============================  ==========================================

Each takes keyword-only settings, steps on 1-D arrays and returns ``(4,)``
scalar-first quaternions; see :class:`estimators.base.AttitudeEstimator`.
"""
from estimators.base import AttitudeEstimator, EstimateTrace
from estimators.dead_reckoning import DeadReckoning
from estimators.dead_reckoning_resets import DeadReckoningWithResets
from estimators.ekf import QuaternionEKF
from estimators.mekf import MultiplicativeEKF
from estimators.usque import USQUE

#: Command-line name → class: the workshop's three in the order it introduces
#: them, then the flight filters. Adding an estimator is one line here.
ESTIMATORS = {cls.name: cls for cls in (DeadReckoning, DeadReckoningWithResets, QuaternionEKF,
                                        MultiplicativeEKF, USQUE)}

__all__ = ["ESTIMATORS", "AttitudeEstimator", "DeadReckoning", "DeadReckoningWithResets",
           "EstimateTrace", "MultiplicativeEKF", "QuaternionEKF", "USQUE"]
