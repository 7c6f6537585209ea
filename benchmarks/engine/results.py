"""What a batch of runs leaves: the kernels' record (:func:`new_record`:
accumulators, histograms, traces, NEES and NIS sums, health counters), and
the numbers reported from it (:class:`BatchResult`): per-run statistics —
Welford's mean and variance, max and final value exactly, the median from a
log-spaced histogram of the error (:data:`HISTOGRAM_BINS` bins from
:data:`HISTOGRAM_MIN_DEG` to 180°, relative error below
:data:`MEDIAN_RELATIVE_ERROR`), exact with kept traces — and the streamed
consistency, NaN from the step a run diverged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchmarks.metrics import STAT_COLUMNS, attitude_error_deg
from benchmarks.scenario import Scenario
from benchmarks.simulation import simulate_truth

#: The median histogram: 128 bins per octave (the error's float exponent and
#: top 7 mantissa bits) from 2⁻²⁰ ≈ 9.5e-7 degrees up, plus one bin below.
HISTOGRAM_MIN_DEG = 2.0 ** -20
_FIRST_BITS = int(np.array([HISTOGRAM_MIN_DEG]).view(np.int64)[0]) >> 45
HISTOGRAM_BINS = 1 + 128 * 28
#: A bin spans at most 2⁻⁷ of its lower edge, which bounds the histogram
#: median's relative error (for medians above HISTOGRAM_MIN_DEG): 0.78 %.
MEDIAN_RELATIVE_ERROR = 2.0 ** -7
#: The health counters' names, in the kernel's order (common.CHECKS ...).
HEALTH_COLUMNS = ("checks", "norm_off", "asymmetric", "not_positive_definite", "non_finite",
                  "worst_norm_deviation", "worst_relative_asymmetry")


@dataclass
class BatchResult:
    """Per-run statistics (and, if kept, estimates) of a batch.

    ``statistics[name][column]`` is ``(B,)`` for each name in ``estimators``
    and each column of :data:`benchmarks.metrics.STAT_COLUMNS`;
    ``estimates[name]`` is ``(B, N, 4)`` when traces were kept.
    """

    runs: object                 # the batch's benchmarks.engine.batch.RunTable
    estimators: tuple
    statistics: dict
    #: Per estimator ``(B,)``: the step where each run's estimate or
    #: covariance stopped being finite, -1 where it never did. A diverged
    #: run's statistics are NaN, never a number.
    diverged_step: dict = None
    estimates: dict | None = None
    #: With traces, per estimator that reports a covariance: ``(B, N, 3)``, the
    #: variance (rad²) of each body axis of its output's attitude error at
    #: every step, NaN from the step it diverged.
    attitude_variances: dict | None = None
    #: The last step's true gyro bias ``(B, 3)`` and, for the MEKF, its
    #: output bias estimate ``(B, 3)`` and 6x6 covariance ``(B, 6, 6)``.
    final: dict | None = None
    #: With ``consistency=True``: per estimator, ``time_s`` (S,) of the NEES
    #: samples, ``nees_samples`` (B, S), ``nees_time_average`` (B,),
    #: ``nis_mean`` (B,) and ``nis_dof``; on the engine also
    #: ``likelihood_sum`` (B,), Σ (ln det S + yᵀ S⁻¹ y) over every applied
    #: update (tracker and vectors), and ``updates`` (B,), their number.
    consistency: dict | None = None
    #: With ``health=True``: per estimator, a dict of ``(B,)`` arrays named as
    #: :data:`HEALTH_COLUMNS` (see :func:`benchmarks.engine.kernels.common.check_health`).
    health: dict | None = None
    #: With ``error_every`` = m > 0: ``error_samples[name]`` ``(B, S)``, each
    #: estimator's error (degrees) at steps 0, m, 2m, ... (``sample_time_s``).
    error_samples: dict | None = None
    sample_time_s: np.ndarray | None = None
    #: Per estimator whose kernel gates (``GATING``): ``(B, S)``, each run's
    #: vector readings rejected by gating, per sensor in the scenario's order.
    rejected: dict | None = None
    #: From :func:`benchmarks.engine.runner.run_many`: per estimator, what its
    #: runs made of their readings (:class:`benchmarks.sensor_use.Usage`).
    usage: dict | None = None

    def frame(self) -> pd.DataFrame:
        """Tidy: one row per (run, estimator) with the run's settings and statistics."""
        parts = []
        for name in self.estimators:
            part = pd.DataFrame({"run": np.arange(len(self.runs)), "seed": self.runs.seeds,
                                 "estimator": name})
            for setting in list(self.runs.__dataclass_fields__)[1:]:    # the per-run settings
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


def bin_edge(index: np.ndarray) -> np.ndarray:
    """Lower edge in degrees of histogram bin ``index`` (≥ 1)."""
    bits = (np.asarray(index, dtype=np.int64) - 1 + _FIRST_BITS) << 45
    return bits.view(np.float64)


def histogram_median(hist: np.ndarray, count: int) -> np.ndarray:
    """Median estimate per row of ``hist`` ``(B, bins)``, degrees.

    The median's rank is located in the cumulative counts and interpolated
    linearly within its bin. Only the bins some run holds are summed (a
    few hundred of the 3,585: the sums a fifth of a 1024-run batch's
    statistics before); those below are empty for every run.
    """
    held = np.flatnonzero(hist.any(axis=0))
    low_bin = int(held[0]) if len(held) else 0
    high_bin = int(held[-1]) + 1 if len(held) else 1
    cumulative = np.cumsum(hist[:, low_bin:high_bin], axis=1, dtype=np.int64)
    rank = (count - 1) / 2.0          # zero-based; halfway for an even count
    reached = cumulative[:, -1] > rank
    inside = np.argmax(cumulative > rank, axis=1)
    index = np.where(reached, inside + low_bin, 0)
    rows = np.arange(len(hist))
    before = np.where(reached & (inside > 0), cumulative[rows, inside - 1], 0)
    # A diverged run's histogram stops short of the rank (its bin count may
    # be 0): its median is NaN'd with its other statistics.
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = (rank - before + 0.5) / hist[rows, index]
    safe = np.maximum(index, 1)
    low, high = bin_edge(safe), bin_edge(safe + 1)
    return np.where(index == 0, 0.0, low + fraction * (high - low))


def new_record(names, n_runs: int, n_steps: int, keep_traces: bool, consistency: bool,
                nees_every: int, settle_steps: int, health: bool, error_every: int,
                n_sensors: int = 0, full_state: bool = False):
    """The kernels' outputs, one row per estimator in ``names``; with traces
    and ``full_state``, each output's whole 6x6 covariance and bias too
    (:func:`benchmarks.engine.kernels.common.keep_output`)."""
    from benchmarks.engine.kernels.common import (FULL_STATE_WIDTH, N_ACCUMULATORS, N_HEALTH,
                                                  Record)
    rows = len(names)
    n_samples = -(-n_steps // nees_every) if consistency else 0
    return Record(
        stats=np.zeros((rows, n_runs, N_ACCUMULATORS)),
        diverged=np.full((rows, n_runs), -1, dtype=np.int64),
        hist=np.zeros((rows, n_runs, HISTOGRAM_BINS), dtype=np.uint32),
        hist_first_bits=_FIRST_BITS,
        traces=(np.zeros((rows, n_runs, n_steps, 4)) if keep_traces
                else np.zeros((rows, 0, 0, 4))),
        keep_traces=bool(keep_traces),
        variances=np.zeros((rows, n_runs, n_steps, FULL_STATE_WIDTH if full_state else 6)
                           if keep_traces else (rows, 0, 0, 6)),
        error_every=error_every,
        error_samples=np.zeros((rows, n_runs, -(-n_steps // error_every) if error_every else 0)),
        consistency=bool(consistency), nees_every=nees_every,
        settle=min(settle_steps, n_steps - 1),
        nees_samples=np.zeros((rows, n_runs, n_samples)), nees_sum=np.zeros((rows, n_runs)),
        nis_sum=np.zeros((rows, n_runs)), nis_count=np.zeros((rows, n_runs)),
        likelihood=np.zeros((rows, n_runs, 2)),
        check_health=bool(health), health=np.zeros((rows, n_runs if health else 0, N_HEALTH)),
        rejected=np.zeros((rows, n_runs, n_sensors), dtype=np.int64))


def batch_result(scenario, runs, kernels, objects, states, record,
                 sensors) -> BatchResult:
    """The batch's numbers as :class:`BatchResult` reports them (``sensors``:
    one kernel's SensorState; every kernel's holds the same numbers)."""
    names, n_steps = tuple(kernels), scenario.n_steps
    statistics = {name: _statistics(scenario, record, row, n_steps)
                  for row, name in enumerate(names)}
    checked = {name: _consistency(record, row, n_steps, scenario.dt,
                                  kernels[name].nis_dof(objects[name]))
               for row, name in enumerate(names) if record.consistency
               and getattr(kernels[name], "REPORTS_COVARIANCE", False)}
    final = {"gyro_bias_radps": sensors.bias_last}
    for name in names:
        report = getattr(kernels[name], "final", None)
        extra = report(states[name], objects[name]) if report is not None else None
        if extra:
            final[name] = extra
    error_every = record.error_every
    return BatchResult(
        runs=runs, estimators=names, statistics=statistics,
        diverged_step={name: record.diverged[row].copy() for row, name in enumerate(names)},
        estimates={name: record.traces[row] for row, name in enumerate(names)}
        if record.keep_traces else None,
        attitude_variances={name: _variances(record, row) for row, name in enumerate(names)
                            if getattr(kernels[name], "REPORTS_COVARIANCE", False)}
        if record.keep_traces else None,
        final=final, consistency=checked or None,
        health={name: dict(zip(HEALTH_COLUMNS, record.health[row].T.copy()))
                for row, name in enumerate(names)} if record.check_health else None,
        error_samples={name: record.error_samples[row] for row, name in enumerate(names)}
        if error_every else None,
        sample_time_s=np.arange(0, n_steps, error_every) * scenario.dt if error_every else None,
        rejected={name: record.rejected[row].copy() for row, name in enumerate(names)
                  if getattr(kernels[name], "GATING", False)})


def _variances(record, row: int) -> np.ndarray:
    """One estimator's kept attitude variances, NaN from the step it diverged."""
    diverged, variances = record.diverged[row], record.variances[row, ..., :3]
    steps = np.arange(variances.shape[1])
    lost = (diverged[:, None] >= 0) & (steps >= diverged[:, None])
    return np.where(lost[:, :, None], np.nan, variances)


def _statistics(scenario: Scenario, record, row: int, n_steps: int) -> dict:
    """One estimator's per-run statistics from its accumulators (NaN where diverged)."""
    from benchmarks.engine.kernels.common import FINAL, M2, MAX, MEAN
    stats = record.stats[row]
    mean, m2 = stats[:, MEAN], stats[:, M2]
    std = np.sqrt(m2 / (n_steps - 1)) if n_steps > 1 else np.zeros(len(mean))
    if record.keep_traces:
        errors = attitude_error_deg(simulate_truth(scenario).q_true, record.traces[row])
        median = np.median(errors, axis=1)
    else:
        median = histogram_median(record.hist[row], n_steps)
    columns = {"mean_deg": mean.copy(), "median_deg": median, "std_deg": std,
               "three_sigma_deg": 3.0 * std, "rms_deg": np.sqrt(mean * mean + m2 / n_steps),
               "max_deg": stats[:, MAX].copy(), "final_deg": stats[:, FINAL].copy()}
    for column in STAT_COLUMNS:     # a diverged run has no statistics
        columns[column][record.diverged[row] >= 0] = np.nan
    return columns


def _consistency(record, row: int, n_steps: int, dt: float, nis_dof: int) -> dict:
    """One estimator's streamed NEES and NIS (NaN where the run diverged)."""
    diverged = record.diverged[row]
    lost = diverged >= 0
    every = record.nees_every
    return {"time_s": np.arange(0, n_steps, every) * dt,
            "nees_samples": _nan_from(record.nees_samples[row],
                                      np.where(lost, -(-diverged // every), -1)),
            "nees_time_average": np.where(lost, np.nan,
                                          record.nees_sum[row] / (n_steps - record.settle)),
            # No reading applied (no star tracker, or every reading gated): no NIS.
            "nis_mean": np.where(lost | (record.nis_count[row] == 0), np.nan,
                                 record.nis_sum[row] / np.maximum(record.nis_count[row], 1)),
            "nis_dof": nis_dof,
            # Over every applied update: Σ (ln det S + yᵀ S⁻¹ y), and their number.
            "likelihood_sum": np.where(lost, np.nan, record.likelihood[row][:, 0]),
            "updates": record.likelihood[row][:, 1].copy()}
