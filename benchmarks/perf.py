"""Speed benchmark: ``python -m benchmarks.perf``. Prints, never asserts.

Times one 50-s run of the default scenario for each workshop estimator on
the per-step (filterpy) path: the median of several repeats of
``estimator.run`` on the same sensor data, plus the truth and sensor
simulation once.
"""
from __future__ import annotations

import argparse
import statistics
import time

from benchmarks.scenario import Scenario
from benchmarks.simulation import (
    WORKSHOP_ESTIMATORS,
    build_estimator,
    simulate_sensors,
    simulate_truth,
)


def _median_seconds(func, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def per_run_seconds(scenario: Scenario, repeats: int = 5) -> dict[str, float]:
    """Median seconds of one ``run`` of each workshop estimator on ``scenario``."""
    truth = simulate_truth(scenario)
    data = simulate_sensors(scenario, truth, seed=0)
    results = {}
    for name in WORKSHOP_ESTIMATORS:
        estimator = build_estimator(name, scenario)
        results[name] = _median_seconds(
            lambda: estimator.run(data.omega_meas_radps, data.star_tracker_quat, data.available),
            repeats)
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf", description=__doc__)
    parser.add_argument("--repeats", type=int, default=5, help="repeats per timing (median)")
    args = parser.parse_args(argv)
    scenario = Scenario()
    start = time.perf_counter()
    truth = simulate_truth(scenario)
    simulate_sensors(scenario, truth, seed=0)
    print(f"truth and sensors, {scenario.tstop:g} s at {1 / scenario.dt:g} Hz: "
          f"{time.perf_counter() - start:.3f} s")
    steps = scenario.n_steps
    for name, seconds in per_run_seconds(scenario, args.repeats).items():
        print(f"{name:<22} one {scenario.tstop:g}-s run: {seconds:.3f} s "
              f"({steps / seconds:,.0f} steps/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
