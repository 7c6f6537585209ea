"""Soak benchmark: ``python -m benchmarks.soak``. Prints, never asserts.

Every estimator of the batched engine runs ten million steps (by default) on
the flight scenario's sensors (:file:`scenarios/flight.toml` lengthened:
about 11.6 days at 10 Hz), one run per core, with the kernel's health checks
on (:func:`benchmarks.engine.kernels.common.check_health`, after every update and
every propagation): |q| within 1e-12 of 1, covariances symmetric to 1e-12 of
their largest diagonal entry, positive definite, finite. It reports

1. the checks made and the failures of each kind, per estimator;
2. whether the error is stationary: its RMS and the filters' mean NEES over
   the first and the last tenth of the run, and the difference of the mean
   square errors in standard errors (batch means, :data:`STATIONARY_Z`). Dead
   reckoning has no measurements, so its error is expected to grow: it is
   shown, not judged;
3. the peak resident memory of the whole process, beside that of the same
   soak one tenth as long, run first as a separate process: the engine
   streams the truth and the noise in blocks, so the two should be alike.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time

import numpy as np

from benchmarks.metrics import ARCSEC_PER_DEG
from benchmarks.shipped import FLIGHT_SCENARIO, shipped_file
from benchmarks.output import progress
from benchmarks.scenario import Scenario

#: A filter's error counts as stationary when its mean square error over the
#: last tenth differs from the first tenth's by less than this many standard
#: errors. The errors are correlated in time (over the bias estimate's time
#: constant), so each tenth's standard error comes from batch means: the
#: tenth of every run cut into BATCHES batches, whose means are close to
#: independent.
STATIONARY_Z = 3.0
BATCHES = 10
#: Estimators whose error has no measurement to hold it: expected to drift.
DRIFTING = ("dead-reckoning",)


def peak_rss_mib() -> float:
    """This process's peak resident memory (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def soak(steps: int, runs: int, every: int, quiet: bool = False):
    """Run the soak; returns (scenario, BatchResult, seconds)."""
    from benchmarks.engine import ENGINE_ESTIMATORS, make_runs, run_batch
    base = Scenario.from_toml(shipped_file(FLIGHT_SCENARIO))
    scenario = base.replace(tstop=(steps - 1) * base.dt)
    start = time.perf_counter()
    with progress(total=scenario.n_steps, desc="soak", unit="step", quiet=quiet) as bar:
        batch = run_batch(scenario, make_runs(scenario, range(runs)), ENGINE_ESTIMATORS,
                          health=True, consistency=True, nees_every=every,
                          settle_steps=scenario.n_steps // 10, error_every=every,
                          progress_bar=bar)
    return scenario, batch, time.perf_counter() - start


def tenths(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first and the last tenth of ``(B, S)`` samples, ``(B, S // 10)`` each."""
    tenth = max(1, samples.shape[1] // 10)
    return samples[:, :tenth], samples[:, -tenth:]


def batch_mean(values: np.ndarray) -> tuple[float, float]:
    """Mean of ``(B, T)`` values and its standard error from batch means."""
    usable = values.shape[1] // BATCHES * BATCHES
    if usable == 0:
        return float(np.mean(values)), float("nan")
    means = values[:, :usable].reshape(len(values), BATCHES, -1).mean(axis=2).ravel()
    return float(np.mean(means)), float(np.std(means, ddof=1) / np.sqrt(len(means)))


def report(scenario, batch, seconds: float) -> list[str]:
    lines = [f"soak: {scenario.n_steps:,} steps ({scenario.tstop:,.0f} s at "
             f"{1 / scenario.dt:g} Hz) x {len(batch.runs)} runs, flight sensors, "
             f"{len(batch.estimators)} estimators: {seconds:.0f} s",
             "",
             "health (checked in the kernel after every update and propagation, all runs):",
             f"  {'estimator':<22} {'checks':>12} {'|q| off':>8} {'asym.':>6} {'not PD':>7} "
             f"{'NaN/inf':>8} {'worst ||q|-1|':>14} {'worst asym.':>12}"]
    for name in batch.estimators:
        h = batch.health[name]
        lines.append(
            f"  {name:<22} {h['checks'].sum():>12,.0f} {h['norm_off'].sum():>8,.0f} "
            f"{h['asymmetric'].sum():>6,.0f} {h['not_positive_definite'].sum():>7,.0f} "
            f"{h['non_finite'].sum():>8,.0f} {h['worst_norm_deviation'].max():>14.1e} "
            f"{h['worst_relative_asymmetry'].max():>12.1e}")
    lines += ["", "stationarity (first tenth against last tenth, all runs; error in arcsec):",
              f"  {'estimator':<22} {'RMS first':>10} {'RMS last':>10} {'z':>6} "
              f"{'NEES first':>11} {'NEES last':>10}  verdict (|z| < {STATIONARY_Z:g})"]
    for name in batch.estimators:
        (ms_first, se_first), (ms_last, se_last) = (
            batch_mean(part ** 2) for part in tenths(batch.error_samples[name] * ARCSEC_PER_DEG))
        z = (ms_last - ms_first) / np.hypot(se_first, se_last)
        nees = "" if batch.consistency is None or name not in batch.consistency else \
            "{:>11.2f} {:>10.2f}".format(*(np.mean(part) for part in
                                           tenths(batch.consistency[name]["nees_samples"])))
        finite = np.isfinite(batch.error_samples[name]).all()
        if name in DRIFTING:
            verdict = "drifts (no measurements), as expected"
        elif finite and abs(z) < STATIONARY_Z:
            verdict = "stationary"
        else:
            verdict = "NOT stationary"
        lines.append(f"  {name:<22} {np.sqrt(ms_first):>10.2f} {np.sqrt(ms_last):>10.2f} "
                     f"{z:>6.2f} {nees or ' ' * 22}  {verdict}")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.soak", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=10_000_000,
                        help="steps per run (default 10,000,000)")
    parser.add_argument("--runs", type=int, default=os.cpu_count() or 1,
                        help="runs, each on its own core (default: one per core)")
    parser.add_argument("--every", type=int, default=1000,
                        help="keep the error and NEES every this many steps (default 1000)")
    parser.add_argument("--no-memory-comparison", action="store_true",
                        help="skip the one-tenth-length soak run first for the memory figure")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.steps < 100 or args.runs < 1 or args.every < 1:
        parser.error("--steps must be at least 100, --runs and --every at least 1")

    short_peak = None
    if not args.no_memory_comparison:
        subprocess.run([sys.executable, "-m", "benchmarks.soak", "--steps",
                        str(args.steps // 10), "--runs", str(args.runs), "--every",
                        str(args.every), "--no-memory-comparison", "--quiet"],
                       check=True, stdout=subprocess.DEVNULL)
        short_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    scenario, batch, seconds = soak(args.steps, args.runs, args.every, args.quiet)
    lines = report(scenario, batch, seconds)
    memory = f"peak resident memory, whole process: {peak_rss_mib():,.0f} MiB"
    if short_peak is not None:
        memory += (f" (the same soak at {args.steps // 10:,} steps, its own process: "
                   f"{short_peak:,.0f} MiB)")
    print("\n".join(lines + ["", memory]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
