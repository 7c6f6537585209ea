"""The batched Monte Carlo engine: many runs of the estimators at once,
compiled (:mod:`benchmarks.engine.batch`), with streaming statistics
(:mod:`benchmarks.engine.results`), one
kernel module per estimator (:mod:`benchmarks.engine.kernels`), the one
runner every campaign goes through (:mod:`benchmarks.engine.runner`) and
resumable campaigns on disk (:mod:`benchmarks.engine.campaign`).

The filterpy-based classes in :mod:`estimators` stay the reference; this
engine is their fast twin for campaigns, checked against them to 1e-9.
"""
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "batch": ("ENGINE_ESTIMATORS", "PER_RUN_SETTINGS", "RunTable", "make_runs", "run_batch"),
    "results": ("HEALTH_COLUMNS", "MEDIAN_RELATIVE_ERROR", "BatchResult"),
    "runner": ("run_many",),
})
