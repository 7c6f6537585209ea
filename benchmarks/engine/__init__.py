"""The batched Monte Carlo engine: many runs of the estimators at once,
compiled, with streaming statistics (:mod:`benchmarks.engine.batch`), one
kernel module per estimator (:mod:`benchmarks.engine.kernels`), the one
runner every campaign goes through (:mod:`benchmarks.engine.runner`) and
resumable campaigns on disk (:mod:`benchmarks.engine.campaign`).

The filterpy-based classes in :mod:`estimators` stay the reference; this
engine is their fast twin for campaigns, checked against them to 1e-9.
"""
from benchmarks.engine.batch import (
    ENGINE_ESTIMATORS,
    HEALTH_COLUMNS,
    MEDIAN_RELATIVE_ERROR,
    PER_RUN_SETTINGS,
    BatchResult,
    RunTable,
    make_runs,
    run_batch,
)
from benchmarks.engine.runner import run_many

__all__ = ["ENGINE_ESTIMATORS", "HEALTH_COLUMNS", "MEDIAN_RELATIVE_ERROR", "PER_RUN_SETTINGS",
           "BatchResult", "RunTable", "make_runs", "run_batch", "run_many"]
