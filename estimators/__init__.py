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
import importlib

from dynamics.validation import InvalidParameterError
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

def resolve_estimator(spec: str) -> type:
    """The estimator class ``spec`` names: a registry name (``"mekf"``) or a
    user's own class as ``"package.module:ClassName"``, which must subclass
    :class:`estimators.AttitudeEstimator` (its module importable: installed,
    or on ``PYTHONPATH``)."""
    if spec in ESTIMATORS:
        return ESTIMATORS[spec]
    rule = (f"must be one of {', '.join(ESTIMATORS)}, or package.module:ClassName for your "
            "own AttitudeEstimator subclass")
    module_name, colon, class_name = str(spec).partition(":")
    if not colon or not module_name or not class_name.isidentifier():
        raise InvalidParameterError("estimator", spec, rule)
    try:
        module = importlib.import_module(module_name)
    except Exception as err:      # the user's module: any import failure is reported
        raise InvalidParameterError("estimator", spec, f"cannot import {module_name} "
                                    f"({type(err).__name__}: {err})") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, AttitudeEstimator)):
        raise InvalidParameterError("estimator", spec, f"{class_name} in {module_name} must be "
                                    "a subclass of estimators.AttitudeEstimator")
    return cls


__all__ = ["ESTIMATORS", "AttitudeEstimator", "DeadReckoning", "DeadReckoningWithResets",
           "EstimateTrace", "MultiplicativeEKF", "QuaternionEKF", "USQUE", "resolve_estimator"]
