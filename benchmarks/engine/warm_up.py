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
#: times, the longest first (measured here on a cold cache, each alone, with
#: the helpers they share: the MEKF 57 s, USQUE 53 s, the EKF 17 s and its
#: lanes kernel about 10 s more, dead reckoning with and without resets 14 s;
#: the two groups in parallel, 59 s before the lanes kernels). With the
#: MEKF's lanes kernel (about 35 s more, on a slower day) the EKF went to
#: USQUE's group and dead reckoning to the MEKF's: both groups in parallel,
#: 101 s on that day, where the groups before took 88 s without it.
#: On a slower day still (2026-12-08): the MEKF's two kernels alone 118 s
#: once its lanes kernel called its output's bookkeeping instead of inlining
#: it twice (127 s before); the groups in parallel, USQUE's 104 s and the
#: MEKF's 124 s; dead reckoning with resets (9 s) then went to USQUE's
#: group: 123 s against the MEKF's group's 120 s, in parallel.
#: The vector sensors' compiled readings (:mod:`sensors.sun_faces`,
#: :mod:`sensors.vector_arithmetic`, about 8 s: each function twice, for the
#: per-run path's arrays and the engine's views) go with the first group.
GROUPS = (("usque", "ekf", "dead-reckoning-resets", "vector-sensors"),
          ("mekf", "dead-reckoning"))


def compile_kernels(names) -> tuple:
    """Run the kernels of ``names`` once on a short workshop run, which
    compiles them (or reads them from the cache); returns ``names``."""
    from benchmarks.engine.batch import make_runs, run_batch
    from benchmarks.scenario import Scenario
    scenario = Scenario(tstop=0.2)
    kernels = tuple(name for name in names if name != "vector-sensors")
    # With the NEES streamed, the one-run kernels; statistics alone, the
    # EKF's and the MEKF's lanes kernels (kernels.ekf_lanes, mekf_lanes) too.
    run_batch(scenario, make_runs(scenario, [0, 1]), estimators=kernels, consistency=True)
    run_batch(scenario, make_runs(scenario, [0, 1]), estimators=kernels)
    if "vector-sensors" in names:
        _compile_vector_sensors()
    return tuple(names)


def _compile_vector_sensors() -> None:
    """The vector sensors' compiled readings, through the sensors' own calls
    for two runs: into arrays of their own (the per-run path) and into views
    of a block's arrays (the engine's; other array types, compiled apart)."""
    import numpy as np
    from dynamics.environment import References
    from sensors.magnetometer import Magnetometer
    from sensors.sun_sensor import CoarseSunSensors, FineSunSensor
    steps = 3
    references = References(magnetic_field_nT=np.tile([2e4, 0.0, 4e4], (steps, 1)),
                            sun_unit=np.tile([0.0, 0.0, 1.0], (steps, 1)),
                            illumination=np.ones(steps), position_km=None)
    attitudes = np.tile([1.0, 0.0, 0.0, 0.0], (steps, 1))
    sensors = (FineSunSensor(0.1, 1.0, 1.0), CoarseSunSensors(0.01, 1.0, 1.0),
               Magnetometer(100.0, 1.0, 1.0))
    body, variance = np.zeros((2, steps, len(sensors), 3)), np.zeros((2, steps, len(sensors)))
    available = np.zeros((2, steps, len(sensors)), dtype=bool)
    for s, sensor in enumerate(sensors):
        sensor.measure_runs(attitudes, references, [np.random.default_rng(run) for run in (0, 1)])
        sensor.measure_into(attitudes, references, [np.random.default_rng(run) for run in (0, 1)],
                            0, body[:, :, s], variance[:, :, s], available[:, :, s])


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
