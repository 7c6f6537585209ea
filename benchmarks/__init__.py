"""How we compare estimators and show it.

At the top: scenarios, simulation, metrics, bounds and the ``attitude-bench``
command line; ``experiments/`` (what the commands run), ``figures/`` (what
they draw) and ``engine/`` (the batched Monte Carlo engine).

Nothing in the project imports this package; it imports all the others.
"""
from benchmarks.metrics import STAT_COLUMNS, error_statistics, loss
from benchmarks.scenario import Scenario
from benchmarks.simulation import RunResult, SensorData, simulate

__all__ = ["STAT_COLUMNS", "RunResult", "Scenario", "SensorData", "error_statistics", "loss",
           "simulate"]
