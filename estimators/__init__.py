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
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "registry": ("ESTIMATORS", "resolve_estimator"),
    "base": ("AttitudeEstimator", "EstimateTrace"),
    "dead_reckoning": ("DeadReckoning",),
    "dead_reckoning_resets": ("DeadReckoningWithResets",),
    "ekf": ("QuaternionEKF",),
    "mekf": ("MultiplicativeEKF",),
    "usque": ("USQUE",),
    "smoother": ("MekfSmoother",),
})
