"""What we infer: attitude estimators sharing one interface.

=============================  ==========================================
name                           class
=============================  ==========================================
``dead-reckoning``             :class:`DeadReckoning`
``dead-reckoning-resets``      :class:`DeadReckoningWithResets`
``ekf``                        :class:`QuaternionEKF` (filterpy EKF)
``mekf``                       :class:`MultiplicativeEKF` (filterpy KF)
``usque``                      :class:`USQUE` (filterpy UKF)
``mekf-smoother``              :class:`MekfSmoother` (offline: the MEKF
                               forward and backward, fused)
``triad``, ``q-method``,       the static solutions of Wahba's problem
``quest``, ``esoq2``,          (:mod:`estimators.static`, solvers in
``foam``, ``svd``              :mod:`estimators.wahba`)
``madgwick``, ``mahony``       the complementary filters
``madgwick-broad``             (:mod:`estimators.complementary`)
``vqf``, ``vqf-6d``,           other libraries' filters, through adapters
``vqf-offline``, ``fusion``    (:mod:`estimators.peers`, the ``peers`` extra)
=============================  ==========================================

Each takes keyword-only settings, steps on 1-D arrays and returns ``(4,)``
scalar-first quaternions; see :class:`estimators.base.AttitudeEstimator`.
"""
import importlib

from dynamics.validation import InvalidParameterError
from estimators.base import AttitudeEstimator, EstimateTrace
from estimators.complementary import Madgwick, MadgwickBROAD, Mahony
from estimators.dead_reckoning import DeadReckoning
from estimators.dead_reckoning_resets import DeadReckoningWithResets
from estimators.ekf import QuaternionEKF
from estimators.mekf import MultiplicativeEKF
from estimators.peers import PEER_ESTIMATORS
from estimators.smoother import MekfSmoother
from estimators.static import STATIC_ESTIMATORS
from estimators.usque import USQUE

#: Command-line name → class: the workshop's three in the order it introduces
#: them, then the flight filters. Adding an estimator is one line here.
ESTIMATORS = {cls.name: cls for cls in (DeadReckoning, DeadReckoningWithResets, QuaternionEKF,
                                        MultiplicativeEKF, USQUE, MekfSmoother, *STATIC_ESTIMATORS,
                                        Madgwick, MadgwickBROAD, Mahony, *PEER_ESTIMATORS)}

#: What a concrete estimator must override: the base class's raise NotImplementedError.
ABSTRACT_METHODS = ("_step", "reset")


def resolve_estimator(spec: str) -> type:
    """The estimator class ``spec`` names: a registry name (``"mekf"``) or a
    user's own class as ``"package.module:ClassName"``, which must subclass
    :class:`estimators.AttitudeEstimator` and implement its
    :data:`ABSTRACT_METHODS` (its module importable: installed, or on
    ``PYTHONPATH``). Importing the module runs its code: callers reading a
    data file ask the user's consent first (:meth:`benchmarks.Scenario.from_toml`)."""
    if spec in ESTIMATORS:
        return ESTIMATORS[spec]
    rule = (f"must be one of {', '.join(ESTIMATORS)}, or package.module:ClassName for your "
            "own AttitudeEstimator subclass")
    module_name, colon, class_name = str(spec).partition(":")
    if not colon or not module_name or not class_name.isidentifier():
        raise InvalidParameterError("estimator", spec, rule)
    return _checked_class(spec, _imported(spec, module_name), class_name)


def _imported(spec: str, module_name: str):
    try:
        return importlib.import_module(module_name)
    except SystemExit as err:     # a module that ends the process on import: say so, go on
        raise InvalidParameterError("estimator", spec, f"cannot import {module_name}: it "
                                    f"calls sys.exit({err.code!r}) when imported") from None
    except Exception as err:      # the user's module: any import failure is reported
        raise InvalidParameterError("estimator", spec, f"cannot import {module_name} "
                                    f"({type(err).__name__}: {err})") from None


def _checked_class(spec: str, module, class_name: str) -> type:
    """``module``'s class ``class_name``, if it is a concrete estimator."""
    where = module.__name__
    if not hasattr(module, class_name):
        raise InvalidParameterError("estimator", spec, f"module {where} has no class {class_name}")
    cls = getattr(module, class_name)
    if not (isinstance(cls, type) and issubclass(cls, AttitudeEstimator)):
        raise InvalidParameterError("estimator", spec, f"{class_name} in {where} is not an "
                                    "estimator: it must be a subclass of "
                                    "estimators.AttitudeEstimator")
    missing = [method for method in ABSTRACT_METHODS
               if getattr(cls, method) is getattr(AttitudeEstimator, method)]
    if missing:
        raise InvalidParameterError("estimator", spec, f"{class_name} is abstract: it does "
                                    f"not implement {' and '.join(missing)}")
    return cls

__all__ = ["ESTIMATORS", "AttitudeEstimator", "DeadReckoning", "DeadReckoningWithResets",
           "EstimateTrace", "MekfSmoother", "MultiplicativeEKF", "QuaternionEKF", "USQUE",
           "resolve_estimator"]
