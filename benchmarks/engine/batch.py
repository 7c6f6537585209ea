"""Run many realisations of the workshop estimators at once.

A batch is a table of runs that share the scenario's truth and time grid and
may differ in their seed, their sensor noise powers, their star tracker
interval and their EKF ``pc_exponent``. For each run the engine draws the
same random numbers as the per-run path draws for that run's seed
(:func:`benchmarks.simulation.sensor_generators`), in time blocks (the truth
too, see :func:`benchmarks.simulation.truth_blocks`), so the
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
from benchmarks.simulation import (TRUTH_CACHE_STEPS, WORKSHOP_ESTIMATORS, sensor_generators,
                                   simulate_truth, truth_blocks)
from dynamics.validation import InvalidParameterError, seed_values
from estimators import ESTIMATORS
from sensors.star_tracker import RotationStarTracker, steps_between_readings

#: Steps advanced per kernel call. It bounds the noise buffer (B × 2500 × 3
#: floats, 61 MB at B = 1024) whatever the run length; larger blocks mean
#: fewer, longer calls into numpy's generators, which then overlap better on
#: two threads (numpy releases the GIL while it fills).
BLOCK_STEPS = 2500
#: The median histogram: 128 bins per octave (the error's float exponent and
#: top 7 mantissa bits) from 2⁻²⁰ ≈ 9.5e-7 degrees up, plus one bin below.
HISTOGRAM_MIN_DEG = 2.0 ** -20
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


def seed_range(first: int, count: int) -> np.ndarray:
    """Seeds ``first, first + 1, …`` (``count`` of them) as int64, exact up to
    2⁶³ - 1 (``np.arange(first, first + count)`` would turn to float64 there)."""
    return np.arange(count, dtype=np.int64) + np.int64(first)


def whole_number(name: str, value, minimum: int) -> int:
    """``value`` as an int if it is a whole number >= ``minimum`` (not a bool)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < minimum:
        raise InvalidParameterError(name, value, f"must be a whole number >= {minimum}")
    return int(value)


def checked_estimators(estimators) -> tuple:
    """The engine estimators named in ``estimators`` (a list of names), in slot order."""
    if isinstance(estimators, str) or not hasattr(estimators, "__iter__"):
        raise InvalidParameterError("estimators", estimators, "must be a list of names, e.g. "
                                    f"[{estimators!r}], not a single string")
    names = list(estimators)
    for name in names:
        if not isinstance(name, str) or name not in ENGINE_ESTIMATORS:
            raise InvalidParameterError("estimators", name,
                                        f"must be one of {', '.join(ENGINE_ESTIMATORS)}")
    if not names or len(set(names)) != len(names):
        raise InvalidParameterError("estimators", names, "must name at least one estimator, "
                                    "each once")
    return tuple(name for name in ENGINE_ESTIMATORS if name in names)


def checked_runs(scenario: Scenario, runs) -> RunTable:
    """``runs`` as the kernel needs it: a :class:`RunTable` of equal-length,
    non-empty 1-D columns, whole seeds, and settings the scenario accepts."""
    if not isinstance(scenario, Scenario):
        raise InvalidParameterError("scenario", type(scenario).__name__,
                                    "must be a benchmarks.scenario.Scenario")
    if not isinstance(runs, RunTable):
        raise InvalidParameterError("runs", type(runs).__name__,
                                    "must be a RunTable (see make_runs)")
    lengths = {name: np.shape(getattr(runs, name)) for name in RunTable.__dataclass_fields__}
    if any(len(shape) != 1 for shape in lengths.values()) or \
            len(set(lengths.values())) != 1 or not lengths["seeds"][0]:
        raise InvalidParameterError("runs", {name: shape for name, shape in lengths.items()},
                                    "every column must be 1-D, of the same length, not empty")
    columns = {}
    for name in PER_RUN_SETTINGS:
        column = np.asarray(getattr(runs, name))
        if column.dtype.kind not in "iuf":
            raise InvalidParameterError(f"runs.{name}", column, "must be real numbers")
        columns[name] = np.ascontiguousarray(column, dtype=float)
        for value in np.unique(columns[name]):
            scenario.replace(**{name: float(value)})     # as the scenario validates it
    return RunTable(np.ascontiguousarray(seed_values("runs.seeds", runs.seeds)), **columns)


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
    seeds = seed_values("seed", seeds)
    try:
        seeds, *values = np.broadcast_arrays(seeds,
                                             *(np.asarray(columns[n]) for n in PER_RUN_SETTINGS))
    except ValueError:
        raise InvalidParameterError("settings", {n: np.shape(columns[n]) for n in columns},
                                    "must broadcast with the seeds") from None
    return checked_runs(scenario, RunTable(seeds, *values))


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
    #: Per estimator ``(B,)``: the step where each run's estimate or
    #: covariance stopped being finite, -1 where it never did. A diverged
    #: run's statistics are NaN, never a number.
    diverged_step: dict = None
    estimates: dict | None = None
    #: The last step's true gyro bias ``(B, 3)`` and, for the MEKF, its
    #: output bias estimate ``(B, 3)`` and 6x6 covariance ``(B, 6, 6)``.
    final: dict | None = None
    #: With ``consistency=True``: per estimator, ``time_s`` (S,) of the NEES
    #: samples, ``nees_samples`` (B, S), ``nees_time_average`` (B,),
    #: ``nis_mean`` (B,) and ``nis_dof``.
    consistency: dict | None = None
    #: With ``health=True``: per estimator, a dict of ``(B,)`` arrays named as
    #: :data:`HEALTH_COLUMNS` (see :func:`benchmarks.engine.kernels._check_health`).
    health: dict | None = None
    #: With ``error_every`` = m > 0: ``error_samples[name]`` ``(B, S)``, each
    #: estimator's error (degrees) at steps 0, m, 2m, ... (``sample_time_s``).
    error_samples: dict | None = None
    sample_time_s: np.ndarray | None = None

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
            part["diverged_step"] = self.diverged_step[name]
            parts.append(part)
        return pd.concat(parts, ignore_index=True)


def _nan_from(samples: np.ndarray, first: np.ndarray) -> np.ndarray:
    """``samples`` ``(B, S)`` with row ``b`` NaN from column ``first[b]`` on
    (``first < 0``: untouched)."""
    columns = np.arange(samples.shape[1])
    return np.where((first[:, None] >= 0) & (columns >= first[:, None]), np.nan, samples)


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


def _fill_normals(generators, gyro_out, star_out, star_counts, uniforms_out, threads):
    """Draw each run's next block of random numbers, in the per-run path's order."""
    def fill(indices):
        for r in indices:
            gyro_rng, star_rng, dropout_rng = generators[r]
            gyro_rng.standard_normal(out=gyro_out[r])
            if star_counts[r]:
                star_rng.standard_normal(out=star_out[r, :star_counts[r]])
                if uniforms_out.shape[1]:
                    dropout_rng.random(out=uniforms_out[r, :star_counts[r]])

    if threads <= 1 or len(generators) < 2 * threads:
        fill(range(len(generators)))
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(fill, np.array_split(np.arange(len(generators)), threads)))


#: Every estimator with a kernel, in the kernel's slot order.
ENGINE_ESTIMATORS = ("dead-reckoning", "dead-reckoning-resets", "ekf", "mekf")


@dataclass(frozen=True)
class _Estimators:
    """The settings the kernel needs, read off the per-run classes themselves
    (built with ``from_scenario``), so the two paths cannot disagree on them."""

    dead_reckoning: object
    resets: object
    ekf: object
    mekf: list      # one MultiplicativeEKF per run (shared where settings repeat)


def _reference_estimators(scenario: Scenario, runs: RunTable, with_mekf: bool) -> _Estimators:
    cache = {}
    mekf = []
    for i in range(len(runs) if with_mekf else 0):
        key = tuple(float(getattr(runs, name)[i]) for name in
                    ("gyro_noise", "star_tracker_noise", "time_between_measurements"))
        if key not in cache:
            case = scenario.replace(gyro_noise=key[0], star_tracker_noise=key[1],
                                    time_between_measurements=key[2])
            cache[key] = ESTIMATORS["mekf"].from_scenario(case)
        mekf.append(cache[key])
    return _Estimators(dead_reckoning=ESTIMATORS["dead-reckoning"].from_scenario(scenario),
                       resets=ESTIMATORS["dead-reckoning-resets"].from_scenario(scenario),
                       ekf=ESTIMATORS["ekf"].from_scenario(scenario), mekf=mekf)


#: The health counters' names, in the kernel's order (kernels.CHECKS ...).
HEALTH_COLUMNS = ("checks", "norm_off", "asymmetric", "not_positive_definite", "non_finite",
                  "worst_norm_deviation", "worst_relative_asymmetry")


#: Estimators whose kernels stream NEES and NIS (they report a covariance).
CONSISTENCY_ESTIMATORS = ("ekf", "mekf")


def run_batch(scenario: Scenario, runs: RunTable, estimators=WORKSHOP_ESTIMATORS,
              keep_traces: bool = False, block_steps: int = BLOCK_STEPS,
              threads: int | None = None, consistency: bool = False,
              nees_every: int = 1, settle_steps: int = 0,
              cache_steps: int = TRUTH_CACHE_STEPS, health: bool = False,
              error_every: int = 0, progress_bar=None) -> BatchResult:
    """Run ``estimators`` (names from :data:`ENGINE_ESTIMATORS`) on every run of ``runs``.

    Parameters
    ----------
    scenario : Scenario
        Truth, time grid, sensor models and every estimator's settings (its
        ``from_scenario``), shared by the runs.
    runs : RunTable
        From :func:`make_runs`.
    estimators : names from :data:`ENGINE_ESTIMATORS`
    keep_traces : bool
        Keep ``(B, N, 4)`` estimates per estimator; the median is then exact.
    block_steps : int
        Steps per kernel call (results do not depend on it).
    threads : int, optional
        Threads drawing random numbers (default: one per core).
    consistency : bool
        Stream the attitude NEES of the estimators in
        :data:`CONSISTENCY_ESTIMATORS` (sampled every ``nees_every`` steps,
        and its per-run average from ``settle_steps`` on) and their
        star-tracker NIS (per-run average); see ``BatchResult.consistency``.
        No traces are needed.
    cache_steps : int
        Longest run whose truth is taken whole from the cache; longer runs
        integrate it block by block (the same numbers), so memory stays flat.
    health : bool
        Check every estimator's state inside the kernel, after each update and
        each propagation: |q| = 1, the covariance symmetric, positive definite
        and finite; counted in ``BatchResult.health``. Off by default (it
        costs a Cholesky factorisation per check).
    error_every : int
        If > 0, keep every estimator's error every that many steps
        (``BatchResult.error_samples``): the shape of a long run's error
        without keeping its traces.
    progress_bar : tqdm-like, optional
        Updated with the steps of each block as it is done.
    """
    from benchmarks.engine import kernels
    from numba import get_num_threads

    # Every argument is checked before compiled code sees it: the kernel
    # trusts shapes and lengths, so a bad table would read or write out of bounds.
    runs = checked_runs(scenario, runs)
    estimators = checked_estimators(estimators)
    block_steps, nees_every, cache_steps, error_every = (
        whole_number("block_steps", block_steps, 1), whole_number("nees_every", nees_every, 1),
        whole_number("cache_steps", cache_steps, 0), whole_number("error_every", error_every, 0))
    settle_steps = whole_number("settle_steps", settle_steps, 0)
    if threads is not None:
        threads = whole_number("threads", threads, 1)
    n_runs, n_steps, dt = len(runs), scenario.n_steps, scenario.dt
    threads = get_num_threads() if threads is None else threads
    enabled = np.array([name in estimators for name in ENGINE_ESTIMATORS])
    reference = _reference_estimators(scenario, runs, "mekf" in estimators)

    # The per-run path's arithmetic, value by value: √(p/dt + σ_u²dt/12) and math.exp.
    gyro = scenario.build_gyro()
    gyro_std = np.array([gyro.reading_std(p, dt, gyro.bias_random_walk) for p in runs.gyro_noise])
    star_tracker = scenario.build_star_tracker()
    rotation_model = isinstance(star_tracker, RotationStarTracker)
    star_std = np.array([math.sqrt(p / dt) for p in runs.star_tracker_noise])
    steps_between = np.array([steps_between_readings(t, dt)
                              for t in runs.time_between_measurements], dtype=np.int64)
    q_variance = np.array([math.exp(pc) for pc in runs.pc_exponent])
    generators = [sensor_generators(int(seed)) for seed in runs.seeds]

    bias_true = np.tile(gyro.initial_bias_radps, (n_runs, 1))
    bias_last = bias_true.copy()
    scale = (np.zeros((3, 3)) if gyro.scale_misalignment is None
             else np.ascontiguousarray(gyro.scale_misalignment))
    if rotation_model:
        star_settings = (np.ascontiguousarray(star_tracker.sigma_rad),
                         np.ascontiguousarray(star_tracker.sensor_to_body),
                         star_tracker.sign == "canonical",
                         float(star_tracker.dropout_probability))
    else:
        star_settings = (np.zeros(3), np.eye(3), False, 0.0)

    dr, resets, ekf = reference.dead_reckoning, reference.resets, reference.ekf
    q_dr = np.tile(dr.initial_attitude, (n_runs, 1))
    q_resets = np.tile(resets.initial_attitude, (n_runs, 1))
    previous_rate = np.zeros((n_runs, 3))
    x_ekf = np.tile(ekf.initial_attitude, (n_runs, 1))
    P_ekf = np.tile(ekf.initial_covariance * np.eye(4), (n_runs, 1, 1))
    R = np.ascontiguousarray(ekf.R)
    mekf = reference.mekf
    q_mekf = np.array([m.initial_attitude for m in mekf]).reshape(-1, 4)
    beta_mekf = np.array([m.initial_bias_radps for m in mekf]).reshape(-1, 3)
    P_mekf = np.array([m.initial_covariance for m in mekf]).reshape(-1, 6, 6)
    mekf_noise = np.array([m.gyro_noise for m in mekf], dtype=float)
    mekf_bias_rw = np.array([m.gyro_bias_random_walk for m in mekf], dtype=float)
    R_mekf = np.array([m.R for m in mekf]).reshape(-1, 3, 3)
    beta_mekf_last = beta_mekf.copy()
    P_mekf_last = P_mekf.copy()
    state = (q_dr, q_resets, previous_rate, x_ekf, P_ekf, q_variance, R, q_mekf, beta_mekf,
             P_mekf, mekf_noise, mekf_bias_rw, R_mekf, beta_mekf_last, P_mekf_last)
    options = (dr.rate_timing == "step-average", resets.rate_timing == "step-average",
               ekf.output == "posterior", bool(mekf) and mekf[0].output == "posterior",
               resets.align_sign, ekf.align_sign)

    # Accumulators only for the estimators that run: row[slot] is each one's row.
    rows = np.cumsum(enabled) - 1
    stats = np.zeros((len(estimators), n_runs, kernels.N_ACCUMULATORS))
    diverged = np.full((len(estimators), n_runs), -1, dtype=np.int64)
    hist = np.zeros((len(estimators), n_runs, HISTOGRAM_BINS), dtype=np.uint32)
    traces = (np.zeros((len(estimators), n_runs, n_steps, 4)) if keep_traces
              else np.zeros((len(estimators), 0, 0, 4)))
    nees_every = max(1, int(nees_every))
    settle_steps = min(max(0, int(settle_steps)), n_steps - 1)
    n_samples = -(-n_steps // nees_every) if consistency else 0
    consistency_arrays = (bool(consistency), nees_every, settle_steps,
                          np.zeros((len(estimators), n_runs, n_samples)),
                          np.zeros((len(estimators), n_runs)), np.zeros((len(estimators), n_runs)),
                          np.zeros((len(estimators), n_runs)))

    health_counts = np.zeros((len(estimators), n_runs if health else 0, kernels.N_HEALTH))
    error_every = max(0, int(error_every))
    error_samples = np.zeros((len(estimators), n_runs,
                              -(-n_steps // error_every) if error_every else 0))

    # Keep the gyro buffer's size whatever its columns (3, or 6 with a bias walk).
    columns = gyro.normals_per_step
    block_steps = max(1, min(int(block_steps) * 3 // columns, n_steps))
    blocks = [(k0, min(k0 + block_steps, n_steps)) for k0 in range(0, n_steps, block_steps)]
    max_readings = -(-block_steps // int(steps_between.min())) + 1
    gyro_buffer = np.empty((n_runs, block_steps, columns))
    star_buffer = np.empty((n_runs, max_readings, 3 if rotation_model else 4))
    uniforms = np.empty((n_runs, max_readings if star_settings[3] > 0 else 0))

    # The truth comes in the same blocks (integrated as it goes for long runs).
    # Draw a block's noise on every core, then advance every run through it.
    for (k0, stop), truth in zip(blocks, truth_blocks(scenario, block_steps, cache_steps)):
        # Readings fall at k ≡ 0 (mod m) in [k0, stop); floor division makes
        # (-1) // m = -1, so the reading at k = 0 is counted too.
        star_counts = (stop - 1) // steps_between - (k0 - 1) // steps_between
        block_gyro = gyro_buffer[:, :stop - k0]
        if not block_gyro.flags.c_contiguous:
            # The last, shorter block gets a buffer of its own: a strided view
            # would compile the kernel a second time (about 40 s, cold).
            gyro_buffer = block_gyro = np.empty((n_runs, stop - k0, columns))
        _fill_normals(generators, block_gyro, star_buffer, star_counts, uniforms, threads)
        gyro_args = (gyro_std, block_gyro, gyro.bias_step_std, scale,
                     gyro.scale_misalignment is not None, gyro.has_bias_model, bias_true,
                     bias_last)
        outage = (star_tracker.in_outage(truth.time_s) if rotation_model
                  else np.zeros(stop - k0, dtype=bool))
        star_args = (rotation_model, star_std, steps_between, star_buffer, star_settings[0],
                     star_settings[1], star_settings[2], outage, star_settings[3], uniforms)
        kernels.advance(k0, n_steps - 1, np.ascontiguousarray(truth.q_true),
                        np.ascontiguousarray(truth.omega_true_radps), dt, gyro_args, star_args,
                        state, enabled, rows, options, stats, diverged, hist, _FIRST_BITS,
                        traces, keep_traces, consistency_arrays, bool(health), health_counts,
                        error_every, error_samples)
        if progress_bar is not None:
            progress_bar.update(stop - k0)

    statistics, estimates = {}, ({} if keep_traces else None)
    for slot, name in zip(rows[enabled], estimators):
        mean, m2 = stats[slot, :, kernels.MEAN], stats[slot, :, kernels.M2]
        std = np.sqrt(m2 / (n_steps - 1)) if n_steps > 1 else np.zeros(n_runs)
        if keep_traces:
            estimates[name] = traces[slot]
            errors = attitude_error_deg(simulate_truth(scenario).q_true, traces[slot])
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
        for column in STAT_COLUMNS:     # a diverged run has no statistics
            statistics[name][column][diverged[slot] >= 0] = np.nan
    checked = {}
    if consistency:
        _, _, _, samples, nees_sum, nis_sum, nis_count = consistency_arrays
        for slot, name in zip(rows[enabled], estimators):
            if name not in CONSISTENCY_ESTIMATORS:
                continue
            lost = diverged[slot] >= 0
            checked[name] = {
                "time_s": np.arange(0, n_steps, nees_every) * dt,
                "nees_samples": _nan_from(samples[slot], np.where(
                    lost, -(-diverged[slot] // nees_every), -1)),
                "nees_time_average": np.where(lost, np.nan,
                                              nees_sum[slot] / (n_steps - settle_steps)),
                "nis_mean": np.where(lost, np.nan,
                                     nis_sum[slot] / np.maximum(nis_count[slot], 1)),
                "nis_dof": (reference.ekf if name == "ekf" else mekf[0]).dim_z}
    final = {"gyro_bias_radps": bias_last}
    if "mekf" in estimators:
        final["mekf"] = {"bias_radps": beta_mekf_last, "covariance": P_mekf_last}
    checked_health = None
    if health:
        checked_health = {name: dict(zip(HEALTH_COLUMNS, health_counts[slot].T.copy()))
                          for slot, name in zip(rows[enabled], estimators)}
    sampled = None
    if error_every:
        sampled = {name: error_samples[slot] for slot, name in zip(rows[enabled], estimators)}
    return BatchResult(runs=runs, estimators=estimators, statistics=statistics,
                       diverged_step={name: diverged[slot].copy()
                                      for slot, name in zip(rows[enabled], estimators)},
                       estimates=estimates, final=final, consistency=checked or None,
                       health=checked_health, error_samples=sampled,
                       sample_time_s=np.arange(0, n_steps, error_every) * dt if error_every
                       else None)


#: Runs per kernel batch in campaigns: large enough to keep both cores busy,
#: small enough that a batch's buffers stay near 100 MB.
CHUNK_RUNS = 1024


def run_chunked(scenario: Scenario, runs: RunTable, estimators=WORKSHOP_ESTIMATORS,
                chunk_runs: int = CHUNK_RUNS, progress_bar=None) -> BatchResult:
    """:func:`run_batch` over ``runs`` in chunks (statistics only), joined.

    Chunking never changes a run's numbers; it bounds memory.
    """
    chunk_runs = whole_number("chunk_runs", chunk_runs, 1)
    runs = checked_runs(scenario, runs)
    parts = []
    for start in range(0, len(runs), chunk_runs):
        part = run_batch(scenario, runs.slice(start, start + chunk_runs), estimators)
        parts.append(part)
        if progress_bar is not None:
            progress_bar.update(len(part.runs))
    statistics = {name: {column: np.concatenate([p.statistics[name][column] for p in parts])
                         for column in STAT_COLUMNS}
                  for name in parts[0].estimators}
    diverged = {name: np.concatenate([p.diverged_step[name] for p in parts])
                for name in parts[0].estimators}
    return BatchResult(runs=runs, estimators=parts[0].estimators, statistics=statistics,
                       diverged_step=diverged)
