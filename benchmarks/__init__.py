"""How we compare estimators and show it.

At the top: scenarios, simulation, metrics, bounds and the ``attitude-bench``
command line; ``experiments/`` (what the commands run), ``figures/`` (what
they draw) and ``engine/`` (the batched Monte Carlo engine).

Nothing in the project imports this package; it imports all the others.
"""
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "metrics": ("STAT_COLUMNS", "error_statistics", "loss"),
    "scenario": ("Scenario",),
    "simulation": ("RunResult", "SensorData", "simulate"),
})
