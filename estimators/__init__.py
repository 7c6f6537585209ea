"""What we infer: attitude estimators sharing one interface.

=============================  ==========================================
name                           class
=============================  ==========================================
``dead-reckoning``             :class:`DeadReckoning`
``dead-reckoning-resets``      :class:`DeadReckoningWithResets`
``ekf``                        :class:`QuaternionEKF` (filterpy EKF)
=============================  ==========================================

Each takes keyword-only settings, steps on 1-D arrays and returns ``(4,)``
scalar-first quaternions; see :class:`estimators.base.AttitudeEstimator`.
"""
from estimators.base import AttitudeEstimator
from estimators.dead_reckoning import DeadReckoning
from estimators.dead_reckoning_resets import DeadReckoningWithResets
from estimators.ekf import QuaternionEKF

#: Command-line name → class, in the order the workshop introduces them.
ESTIMATORS = {cls.name: cls for cls in (DeadReckoning, DeadReckoningWithResets, QuaternionEKF)}

__all__ = ["ESTIMATORS", "AttitudeEstimator", "DeadReckoning", "DeadReckoningWithResets",
           "QuaternionEKF"]
