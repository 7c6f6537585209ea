"""Experiments: what the command line runs, as functions users can call.

=====================  ===============================================
module                 what it does
=====================  ===============================================
``runs``               one run, a comparison, a sweep, the animation
``sweep_parameters``   the settings a sweep can vary
``inspection``         what a logged file holds, and its declaration
``tuning``             Activity 3b: fminbnd-style tuning of pc_exponent
``landscape``          the loss landscape over pc_exponent
``consistency``        NEES/NIS campaigns, verdicts, efficiency
``workshop``           the whole exercise as a report
``flight_study``       the study after it: additive against multiplicative
``replay``             a recorded gyro against an optical reference
=====================  ===============================================

The everyday ones are importable from here: ``experiments.compare(...)``.
"""
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "runs": ("SWEEP_COLUMNS", "TRACE_COLUMNS", "animate", "compare", "flight_comparison_figure",
             "run_one", "sweep", "sweep_scenarios", "write_summary"),
    "sweep_parameters": ("SWEEP_PARAMETERS", "SweepParameter"),
})
