"""Run many realisations of the workshop estimators at once.

A batch is a table of runs that share the scenario's truth and time grid and
may differ in their seed, their sensor noise powers, their star tracker
interval and their EKF ``pc_exponent``. For each run the engine draws the
same random numbers as the per-run path draws for that run's seed
(:func:`benchmarks.simulation.sensor_generators`), in time blocks, so the
results are the per-run path's to rounding (checked to 1e-9 in the tests),
and memory does not grow with the run's length.

Statistics are accumulated as the runs advance: Welford's mean and variance,
max and final value exactly; the median from a log-spaced histogram of the
error (:data:`HISTOGRAM_BINS` bins from :data:`HISTOGRAM_MIN_DEG` to 180°),
whose relative error is below :data:`MEDIAN_RELATIVE_ERROR`. With
``keep_traces=True`` the estimates are kept and the median is exact.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchmarks.metrics import STAT_COLUMNS, attitude_error_deg
from benchmarks.scenario import Scenario
from benchmarks.simulation import WORKSHOP_ESTIMATORS, sensor_generators, simulate_truth
from dynamics.validation import InvalidParameterError
from sensors.star_tracker import steps_between_readings

#: Steps advanced per kernel call. It bounds the noise buffer (B × 2500 × 3
#: floats, 61 MB at B = 1024) whatever the run length; larger blocks mean
#: fewer, longer calls into numpy's generators, which then overlap better on
#: two threads (numpy releases the GIL while it fills).
BLOCK_STEPS = 2500
#: The median histogram: 128 bins per octave (the error's float exponent and
#: top 7 mantissa bits) from 2⁻²⁰ ≈ 9.5e-7 degrees up, plus one bin below.
HISTOGRAM_MIN_DEG = 2.0 ** -20
HISTOGRAM_MAX_DEG = 256.0
_FIRST_BITS = int(np.array([HISTOGRAM_MIN_DEG]).view(np.int64)[0]) >> 45
HISTOGRAM_BINS = 1 + 128 * 28
#: A bin spans at most 2⁻⁷ of its lower edge, which bounds the histogram
#: median's relative error (for medians above HISTOGRAM_MIN_DEG): 0.78 %.
MEDIAN_RELATIVE_ERROR = 2.0 ** -7

#: Settings a run may override, besides its seed.
PER_RUN_SETTINGS = ("gyro_noise", "star_tracker_noise", "time_between_measurements",
                    "pc_exponent")


@dataclass(frozen=True)
class RunTable:
    """The runs of a batch: a seed and the per-run settings, each ``(B,)``."""

    seeds: np.ndarray
    gyro_noise: np.ndarray
    star_tracker_noise: np.ndarray
    time_between_measurements: np.ndarray
    pc_exponent: np.ndarray

    def __len__(self) -> int:
        return len(self.seeds)

    def slice(self, start: int, stop: int) -> "RunTable":
        return RunTable(*(getattr(self, name)[start:stop] for name in self.__dataclass_fields__))

    def take(self, indices) -> "RunTable":
        return RunTable(*(getattr(self, name)[indices] for name in self.__dataclass_fields__))


def make_runs(scenario: Scenario, seeds, **settings) -> RunTable:
    """A run table: ``seeds`` and any of :data:`PER_RUN_SETTINGS` as scalars or
    arrays (broadcast together); missing settings come from ``scenario``.

    Every distinct value is validated as the scenario would validate it.
    """
    unknown = set(settings) - set(PER_RUN_SETTINGS)
    if unknown:
        name = sorted(unknown)[0]
        raise InvalidParameterError(name, settings[name],
                                    f"is not a per-run setting; known: {', '.join(PER_RUN_SETTINGS)}")
    columns = {name: settings.get(name, getattr(scenario, name)) for name in PER_RUN_SETTINGS}
    seeds, *values = np.broadcast_arrays(np.asarray(seeds, dtype=np.int64),
                                         *(np.asarray(columns[n], dtype=float)
                                           for n in PER_RUN_SETTINGS))
    for name, column in zip(PER_RUN_SETTINGS, values):
        for value in np.unique(column):
            scenario.replace(**{name: float(value)})
    if np.any(seeds < 0):
        raise InvalidParameterError("seed", int(seeds.min()), "must be a whole number >= 0")
    return RunTable(np.ascontiguousarray(seeds),
                    *(np.ascontiguousarray(column, dtype=float) for column in values))


@dataclass
class BatchResult:
    """Per-run statistics (and, if kept, estimates) of a batch.

    ``statistics[name][column]`` is ``(B,)`` for each name in ``estimators``
    and each column of :data:`benchmarks.metrics.STAT_COLUMNS`;
    ``estimates[name]`` is ``(B, N, 4)`` when traces were kept.
    """

    runs: RunTable
    estimators: tuple
    statistics: dict
    estimates: dict | None = None

    def frame(self) -> pd.DataFrame:
        """Tidy: one row per (run, estimator) with the run's settings and statistics."""
        parts = []
        for name in self.estimators:
            part = pd.DataFrame({"run": np.arange(len(self.runs)), "seed": self.runs.seeds,
                                 "estimator": name})
            for setting in PER_RUN_SETTINGS:
                part[setting] = getattr(self.runs, setting)
            for column in STAT_COLUMNS:
                part[column] = self.statistics[name][column]
            parts.append(part)
        return pd.concat(parts, ignore_index=True)


def _bin_edge(index: np.ndarray) -> np.ndarray:
    """Lower edge in degrees of histogram bin ``index`` (≥ 1)."""
    bits = (np.asarray(index, dtype=np.int64) - 1 + _FIRST_BITS) << 45
    return bits.view(np.float64)


def histogram_median(hist: np.ndarray, count: int) -> np.ndarray:
    """Median estimate per row of ``hist`` ``(B, bins)``, degrees.

    The median's rank is located in the cumulative counts and interpolated
    linearly within its bin.
    """
    cumulative = np.cumsum(hist, axis=1)
    rank = (count - 1) / 2.0          # zero-based; halfway for an even count
    index = np.argmax(cumulative > rank, axis=1)
    rows = np.arange(len(hist))
    before = np.where(index > 0, cumulative[rows, index - 1], 0)
    fraction = (rank - before + 0.5) / hist[rows, index]
    safe = np.maximum(index, 1)
    low, high = _bin_edge(safe), _bin_edge(safe + 1)
    return np.where(index == 0, 0.0, low + fraction * (high - low))


def _fill_normals(generators, gyro_out, star_out, star_counts, threads):
    """Draw each run's next block of standard normals, in the per-run path's order."""
    def fill(indices):
        for r in indices:
            gyro_rng, star_rng = generators[r][:2]
            gyro_rng.standard_normal(out=gyro_out[r])
            if star_counts[r]:
                star_rng.standard_normal(out=star_out[r, :star_counts[r]])

    if threads <= 1 or len(generators) < 2 * threads:
        fill(range(len(generators)))
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(fill, np.array_split(np.arange(len(generators)), threads)))


def run_batch(scenario: Scenario, runs: RunTable, estimators=WORKSHOP_ESTIMATORS,
              keep_traces: bool = False, block_steps: int = BLOCK_STEPS,
              threads: int | None = None) -> BatchResult:
    """Run ``estimators`` (workshop names) on every run of ``runs``.

    Parameters
    ----------
    scenario : Scenario
        Truth, time grid, EKF ``R``, initial state and covariance (shared).
    runs : RunTable
        From :func:`make_runs`.
    estimators : names from ``estimators.ESTIMATORS``
    keep_traces : bool
        Keep ``(B, N, 4)`` estimates per estimator; the median is then exact.
    block_steps : int
        Steps per kernel call (results do not depend on it).
    threads : int, optional
        Threads drawing random numbers (default: one per core).
    """
    from benchmarks.engine import kernels
    from numba import get_num_threads

    unknown = [name for name in estimators if name not in WORKSHOP_ESTIMATORS]
    if unknown:
        raise InvalidParameterError("estimator", unknown[0],
                                    f"must be one of {', '.join(WORKSHOP_ESTIMATORS)}")
    estimators = tuple(name for name in WORKSHOP_ESTIMATORS if name in estimators)
    truth = simulate_truth(scenario)
    n_runs, n_steps, dt = len(runs), scenario.n_steps, scenario.dt
    threads = get_num_threads() if threads is None else threads
    enabled = np.array([name in estimators for name in WORKSHOP_ESTIMATORS])

    # The per-run path's arithmetic, value by value: √(p/dt) and math.exp.
    gyro_std = np.array([math.sqrt(p / dt) for p in runs.gyro_noise])
    star_std = np.array([math.sqrt(p / dt) for p in runs.star_tracker_noise])
    steps_between = np.array([steps_between_readings(t, dt)
                              for t in runs.time_between_measurements], dtype=np.int64)
    q_variance = np.array([math.exp(pc) for pc in runs.pc_exponent])
    generators = [sensor_generators(int(seed)) for seed in runs.seeds]

    x0 = scenario.initial_state
    q_dr = np.tile(x0, (n_runs, 1))
    q_resets = q_dr.copy()
    x_ekf = q_dr.copy()
    P_ekf = np.tile(scenario.initial_covariance * np.eye(4), (n_runs, 1, 1))
    R = np.ascontiguousarray(scenario.measurement_covariance)
    stats = np.zeros((3, n_runs, kernels.N_ACCUMULATORS))
    hist = np.zeros((3, n_runs, HISTOGRAM_BINS), dtype=np.uint32)
    traces = (np.zeros((3, n_runs, n_steps, 4)) if keep_traces
              else np.zeros((3, 0, 0, 4)))
    q_true = np.ascontiguousarray(truth.q_true)
    omega_true = np.ascontiguousarray(truth.omega_true_radps)

    block_steps = max(1, min(int(block_steps), n_steps))
    blocks = [(k0, min(k0 + block_steps, n_steps)) for k0 in range(0, n_steps, block_steps)]
    max_readings = -(-block_steps // int(steps_between.min())) + 1
    gyro_buffer = np.empty((n_runs, block_steps, 3))
    star_buffer = np.empty((n_runs, max_readings, 4))

    # Draw a block's noise on every core, then advance every run through it.
    for k0, stop in blocks:
        # Readings fall at k ≡ 0 (mod m) in [k0, stop); floor division makes
        # (-1) // m = -1, so the reading at k = 0 is counted too.
        star_counts = (stop - 1) // steps_between - (k0 - 1) // steps_between
        block_gyro = gyro_buffer[:, :stop - k0]
        _fill_normals(generators, block_gyro, star_buffer, star_counts, threads)
        kernels.advance(k0, q_true, omega_true, dt, gyro_std, star_std, steps_between,
                        block_gyro, star_buffer, enabled, q_dr, q_resets, x_ekf, P_ekf,
                        q_variance, R, stats, hist, _FIRST_BITS, traces, keep_traces)

    statistics, estimates = {}, ({} if keep_traces else None)
    for slot, name in enumerate(WORKSHOP_ESTIMATORS):
        if name not in estimators:
            continue
        mean, m2 = stats[slot, :, kernels.MEAN], stats[slot, :, kernels.M2]
        std = np.sqrt(m2 / (n_steps - 1)) if n_steps > 1 else np.zeros(n_runs)
        if keep_traces:
            estimates[name] = traces[slot]
            errors = attitude_error_deg(q_true, traces[slot])
            median = np.median(errors, axis=1)
        else:
            median = histogram_median(hist[slot].astype(np.int64), n_steps)
        statistics[name] = {
            "mean_deg": mean.copy(),
            "median_deg": median,
            "std_deg": std,
            "three_sigma_deg": 3.0 * std,
            "rms_deg": np.sqrt(mean * mean + m2 / n_steps),
            "max_deg": stats[slot, :, kernels.MAX].copy(),
            "final_deg": stats[slot, :, kernels.FINAL].copy(),
        }
    return BatchResult(runs=runs, estimators=estimators, statistics=statistics,
                       estimates=estimates)


#: Runs per kernel batch in campaigns: large enough to keep both cores busy,
#: small enough that a batch's buffers stay near 100 MB.
CHUNK_RUNS = 1024


def run_chunked(scenario: Scenario, runs: RunTable, estimators=WORKSHOP_ESTIMATORS,
                chunk_runs: int = CHUNK_RUNS, progress_bar=None) -> BatchResult:
    """:func:`run_batch` over ``runs`` in chunks (statistics only), joined.

    Chunking never changes a run's numbers; it bounds memory.
    """
    parts = []
    for start in range(0, len(runs), chunk_runs):
        part = run_batch(scenario, runs.slice(start, start + chunk_runs), estimators)
        parts.append(part)
        if progress_bar is not None:
            progress_bar.update(len(part.runs))
    statistics = {name: {column: np.concatenate([p.statistics[name][column] for p in parts])
                         for column in STAT_COLUMNS}
                  for name in parts[0].estimators}
    return BatchResult(runs=runs, estimators=parts[0].estimators, statistics=statistics)
