"""Speed and memory benchmark: ``python -m benchmarks.perf``. Prints, never asserts.

From one run on this machine:

0. the command line's start-up: whole-process seconds of ``--help``,
   ``--version``, a command's ``--help`` and a refused argument (the median
   of ``--repeats``; ``--startup``: this part only);
1. the per-run (filterpy) path: seconds for one 50-s run of each registered
   estimator and its run-steps per second;
2. the batched engine at batch sizes 1, 64 and 1024 — the EKF alone and the
   workshop's three estimators together — in run-steps per second (one
   run-step is one run advanced one step, noise drawing included), and its
   ratio to the filterpy EKF; then every estimator with a kernel at batch
   1024, on the workshop's sensors (with its ratio to the per-run path) and
   on the flight scenario's (bias random walk, rotation star tracker);
3. the wall time of a 73-value × 100-seed loss landscape: its computation,
   and the whole ``attitude-bench landscape`` process (figures and GIF too);
4. the peak resident memory and wall time of a 10,000-run statistics-only
   campaign of the default scenario, run as a separate ``attitude-bench
   montecarlo`` process and read from the operating system's accounting;
5. the vector sensors: the MEKF and USQUE on the CubeSat scenario (6000 s,
   magnetometer, fine and coarse sun sensors, gating), one run on the
   per-run path against 1024 on the engine (``--vectors``: this part only).

The kernel is compiled (or loaded from numba's cache) before timing starts;
that one-off time is printed too.
"""
from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from benchmarks.shipped import FLIGHT_SCENARIO, shipped_file
from benchmarks.scenario import Scenario
from benchmarks.simulation import (
    WORKSHOP_ESTIMATORS,
    build_estimator,
    simulate_sensors,
    simulate_truth,
)
from estimators import ESTIMATORS



def _median_seconds(func, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def per_run_seconds(scenario: Scenario, repeats: int = 5) -> dict[str, float]:
    """Median seconds of one ``run`` of each estimator that can use
    ``scenario``'s sensors (the IMU filters and the static solvers cannot)."""
    from benchmarks.sensor_use import scenario_sensors, usable_estimators
    truth = simulate_truth(scenario)
    data = simulate_sensors(scenario, truth, seed=0)
    results = {}
    for name in usable_estimators(tuple(ESTIMATORS), scenario_sensors(scenario)):
        estimator = build_estimator(name, scenario)
        results[name] = _median_seconds(
            lambda: estimator.run(data.omega_meas_radps, data.star_tracker_quat, data.available),
            repeats)
    return results


def engine_steps_per_second(scenario: Scenario, batch: int, estimators, repeats: int) -> float:
    from benchmarks.engine import make_runs, run_batch
    runs = make_runs(scenario, np.arange(batch))
    seconds = _median_seconds(lambda: run_batch(scenario, runs, estimators), repeats)
    return batch * scenario.n_steps / seconds


def landscape_seconds(scenario: Scenario) -> float:
    from benchmarks.experiments.landscape import compute_landscape, pc_grid
    start = time.perf_counter()
    compute_landscape(scenario, pc_grid(-18, 0, 0.25), seeds=range(100), quiet=True)
    return time.perf_counter() - start


#: The command lines whose start-up is timed: each answers without running anything.
STARTUP_COMMANDS = (("--help",), ("--version",), ("compare", "--help"),
                    ("run", "--estimator", "nope"))
#: The landscape of issue 32's target, as a user types it.
LANDSCAPE_COMMAND = ("landscape", "--pc-min", "-18", "--pc-max", "0", "--pc-step", "0.25",
                     "--seeds", "0-99", "--quiet")


def process_seconds(arguments, repeats: int) -> float:
    """Median whole-process seconds of ``python -m benchmarks ARGUMENTS``
    (start-up included; its output thrown away)."""
    command = [sys.executable, "-m", "benchmarks", *arguments]
    return _median_seconds(lambda: subprocess.run(command, stdout=subprocess.DEVNULL,
                                                  stderr=subprocess.DEVNULL), repeats)


def startup_section(repeats: int) -> None:
    """Part 0: how soon the command line answers."""
    print("command line start-up (whole process, median):")
    for arguments in STARTUP_COMMANDS:
        print(f"  attitude-bench {' '.join(arguments):<28} "
              f"{process_seconds(arguments, max(repeats, 5)):.2f} s")


def landscape_process_seconds(repeats: int) -> float:
    """Median whole-process seconds of :data:`LANDSCAPE_COMMAND`."""
    with tempfile.TemporaryDirectory() as out:
        return process_seconds(LANDSCAPE_COMMAND + ("--out", out), repeats)


def campaign_peak_memory(runs: int) -> tuple[float, float]:
    """(peak MiB, wall seconds) of a statistics-only campaign in a child process."""
    with tempfile.TemporaryDirectory() as out:
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "benchmarks", "montecarlo", "--runs", str(runs),
                        "--out", out, "--quiet"], check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if peak_kib <= before:  # pragma: no cover - an earlier child was larger
        print("note: peak memory not separable from an earlier child process")
    return peak_kib / 1024.0, wall


def vector_section(repeats: int) -> None:
    """Part 5: the CubeSat's filters, per run and at batch 1024 on the engine."""
    from benchmarks.engine import make_runs, run_batch
    from benchmarks.simulation import simulate
    cubesat = Scenario.from_toml(shipped_file("scenarios/cubesat.toml"))
    run_batch(cubesat.replace(tstop=10.0), make_runs(cubesat, [0]), ("mekf", "usque"))
    print(f"\nvector sensors, {cubesat.tstop:g} s of the CubeSat ({cubesat.n_steps} steps):")
    for name in ("mekf", "usque"):
        one = _median_seconds(lambda: simulate(cubesat, [name], seed=0), 1)
        batch = _median_seconds(lambda: run_batch(cubesat, make_runs(cubesat, np.arange(1024)),
                                                  (name,)), repeats)
        print(f"  {name:<6} per run {one:6.2f} s   engine, 1024 runs {batch:6.1f} s "
              f"({batch / 1024 * 1000:.1f} ms a run, {one * 1024 / batch:,.0f}x)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf",
                                     description="Speed and memory benchmark (prints only).")
    parser.add_argument("--repeats", type=int, default=3, help="repeats per timing (median)")
    parser.add_argument("--campaign-runs", type=int, default=10_000,
                        help="runs of the memory campaign (default 10000)")
    parser.add_argument("--vectors", action="store_true",
                        help="only the vector sensors' part (the CubeSat's MEKF and USQUE)")
    parser.add_argument("--startup", action="store_true",
                        help="only the command line's start-up")
    args = parser.parse_args(argv)
    if args.vectors:
        vector_section(args.repeats)
        return 0
    startup_section(args.repeats)
    if args.startup:
        return 0
    scenario = Scenario()
    steps = scenario.n_steps

    print(f"\nscenario: {scenario.tstop:g} s at {1 / scenario.dt:g} Hz ({steps} steps per run)")
    print("\nper-run path (filterpy EKF, MEKF and UKF; hand-written dead reckoning):")
    per_run = per_run_seconds(scenario, max(args.repeats, 3))
    for name, seconds in per_run.items():
        print(f"  {name:<22} {seconds:.3f} s per run   {steps / seconds:>12,.0f} run-steps/s")
    filterpy_rate = steps / per_run["ekf"]

    from benchmarks.engine import ENGINE_ESTIMATORS, make_runs, run_batch
    start = time.perf_counter()
    run_batch(scenario, make_runs(scenario, [0]))
    print(f"\nbatched engine (kernel compile or cache load: {time.perf_counter() - start:.1f} s):")
    rates = {}
    for batch in (1, 64, 1024):
        for label, estimators in (("ekf", ("ekf",)), ("all three", WORKSHOP_ESTIMATORS)):
            rates[batch, label] = engine_steps_per_second(scenario, batch, estimators,
                                                          args.repeats)
            print(f"  batch {batch:>4}  {label:<9} {rates[batch, label]:>14,.0f} run-steps/s")
    print(f"  ratio, batch 1024 EKF to filterpy EKF: {rates[1024, 'ekf'] / filterpy_rate:.0f}x")
    short_flight = Scenario.from_toml(shipped_file(FLIGHT_SCENARIO)).replace(tstop=500.0)
    print("\n  each estimator at batch 1024 (run-steps/s; ratio to its per-run path):")
    print(f"  {'':<22} {'workshop sensors':>22} {'flight sensors':>16}")
    for name in ENGINE_ESTIMATORS:
        workshop = engine_steps_per_second(scenario, 1024, (name,), args.repeats)
        flight = engine_steps_per_second(short_flight, 1024, (name,), args.repeats)
        print(f"  {name:<22} {workshop:>14,.0f} {workshop * per_run[name] / steps:>6,.0f}x "
              f"{flight:>16,.0f}")

    # The campaign's child first: the operating system keeps the largest child's peak.
    peak_mib, wall = campaign_peak_memory(args.campaign_runs)
    print(f"\nlandscape, 73 pc values x 100 seeds: {landscape_seconds(scenario):.1f} s "
          f"computing; {landscape_process_seconds(args.repeats):.1f} s the whole process "
          f"(attitude-bench {' '.join(LANDSCAPE_COMMAND)}, figures and GIF included)")
    print(f"campaign, {args.campaign_runs:,} runs x 3 estimators, statistics only: "
          f"peak {peak_mib:,.0f} MiB, {wall:.1f} s wall (whole process)")
    vector_section(args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
