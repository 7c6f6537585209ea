"""The batched Monte Carlo engine: many runs of the workshop estimators at
once, compiled, with streaming statistics (see :mod:`benchmarks.engine.batch`).

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
    run_chunked,
)

__all__ = ["ENGINE_ESTIMATORS", "HEALTH_COLUMNS", "MEDIAN_RELATIVE_ERROR", "PER_RUN_SETTINGS", "BatchResult", "RunTable", "make_runs",
           "run_batch", "run_chunked"]
