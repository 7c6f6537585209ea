"""Compile the engine's kernels before their first use, two at a time.

Each kernel compiles once per machine and is then read from numba's cache
(``cache=True``), but its first compile takes tens of seconds (the MEKF's,
with the IMU models, about a minute). Where several processes would each
meet a cold kernel at once — the test suite's workers, a Dask cluster's —
they would compile it side by side; :func:`warm_up` compiles every kernel
first, the groups of :data:`GROUPS` in their own processes in parallel, so
that the rest of the work only reads the cache. Running it on a warm cache
costs a second or two.

``python -m benchmarks.engine.warm_up`` does it from the command line.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

#: The kernels compiled together, one group per process: about equal compile
#: times, the longest first (measured here on a cold cache, two processes at
#: a time: the MEKF and USQUE about 55 s each, the EKF 17 s, dead reckoning
#: with resets 6 s, without 5 s). The coarse sun sensors' compiled readings
#: (:mod:`sensors.sun_faces`, a few seconds) go with the first group.
GROUPS = (("usque", "dead-reckoning-resets", "dead-reckoning", "coarse-sun-sensors"),
          ("mekf", "ekf"))


def compile_kernels(names) -> tuple:
    """Run the kernels of ``names`` once on a short workshop run, which
    compiles them (or reads them from the cache); returns ``names``."""
    from benchmarks.engine.batch import make_runs, run_batch
    from benchmarks.scenario import Scenario
    scenario = Scenario(tstop=0.2)
    kernels = tuple(name for name in names if name != "coarse-sun-sensors")
    run_batch(scenario, make_runs(scenario, [0, 1]), estimators=kernels, consistency=True)
    if "coarse-sun-sensors" in names:
        import numpy as np
        from sensors.sun_sensor import CoarseSunSensors
        CoarseSunSensors(0.01, 1.0, 1.0)._sun_vectors(np.eye(6))
    return tuple(names)


def warm_up(processes: int = len(GROUPS)) -> None:
    """Compile every group of :data:`GROUPS`, ``processes`` at a time. The
    cache is first made true to the sources here, before the processes
    start: each then finds it so, and none removes what another compiles."""
    from benchmarks.engine.cache import keep_fresh
    keep_fresh()
    if processes <= 1:
        for names in GROUPS:
            compile_kernels(names)
        return
    with ProcessPoolExecutor(max_workers=processes) as pool:
        list(pool.map(compile_kernels, GROUPS))


if __name__ == "__main__":
    warm_up()
