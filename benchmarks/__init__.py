"""How we compare estimators and show it: scenarios, simulation, metrics,
figures and the ``attitude-bench`` command line.

Nothing in the project imports this package; it imports all the others.
"""
from benchmarks.metrics import STAT_COLUMNS, error_statistics, loss
from benchmarks.scenario import Scenario
from benchmarks.simulation import RunResult, SensorData, simulate

__all__ = ["STAT_COLUMNS", "RunResult", "Scenario", "SensorData", "error_statistics", "loss",
           "simulate"]
