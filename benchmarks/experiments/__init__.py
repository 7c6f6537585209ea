"""Experiments: what the command line runs, as functions users can call.

=====================  ===============================================
module                 what it does
=====================  ===============================================
``runs``               one run, a comparison, a sweep, the animation
``tuning``             Activity 3b: fminbnd-style tuning of pc_exponent
``landscape``          the loss landscape over pc_exponent
``consistency``        NEES/NIS campaigns, verdicts, efficiency
``workshop``           the whole exercise as a report
``flight_study``       the study after it: additive against multiplicative
``replay``             a recorded gyro against an optical reference
=====================  ===============================================

The everyday ones are importable from here: ``experiments.compare(...)``.
"""
from benchmarks.experiments.runs import (
    SWEEP_COLUMNS,
    SWEEP_PARAMETERS,
    TRACE_COLUMNS,
    SweepParameter,
    animate,
    compare,
    flight_comparison_figure,
    run_one,
    sweep,
    sweep_scenarios,
    write_json,
    write_summary,
)

__all__ = ["SWEEP_COLUMNS", "SWEEP_PARAMETERS", "TRACE_COLUMNS", "SweepParameter", "animate",
           "compare", "flight_comparison_figure", "run_one", "sweep", "sweep_scenarios",
           "write_json", "write_summary"]
