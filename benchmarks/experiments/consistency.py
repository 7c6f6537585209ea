r"""Consistency: does a filter know its own error?

For an estimate with error :math:`e_k` (here the body-frame small angle
:math:`\delta\theta`, 3 components, or the bias error) and the covariance
:math:`P_k` the filter reports for it, the normalised estimation error squared

.. math:: \epsilon_k = e_k^\mathsf{T} P_k^{-1} e_k

(:func:`benchmarks.metrics.nees`) is :math:`\chi^2(n)` distributed with
:math:`n` the error's dimension if the filter is consistent (its errors
zero-mean with covariance :math:`P_k`).
Averaged over :math:`N` independent runs (ANEES),
:math:`N \bar\epsilon_k \sim \chi^2(nN)`, which gives the two-sided band a
consistent filter's ANEES falls in with the stated probability (Bar-Shalom,
Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, §5.4). The normalised innovation squared (NIS) of the star
tracker's readings, :math:`y^\mathsf{T} S^{-1} y`, is the same test on what
the filter can check for itself, with the reading's dimension as degrees of
freedom.

Verdicts compare the time-averaged ANEES with that band: inside,
*consistent*; above, *optimistic* (the filter thinks it is better than it
is); below, *pessimistic*. Averaging over time does not widen the
distribution (its mean stays :math:`n`, its variance can only shrink), so the
single-time band is a conservative band for the time average. A value within
:data:`BORDERLINE` of the band's half-width from an edge, on either side,
adds "(borderline)": more runs narrow the band (as :math:`1/\sqrt{N}`) and
settle it.

**Efficiency** is the estimator's RMS error over the bound's RMS
(:mod:`benchmarks.bounds`), both from the settle time on (the estimator's
from its errors sampled at a step that shares no factor with the readings'
period, the bound's over every step), with the bound taken before or after
each step's reading as the estimator outputs (its ``output``). Both start after the settle time
because the bound's step-0 prior is the filters' declared one, while the
runs start wherever the scenario puts them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import chi2

from benchmarks.metrics import angle_unit
from dynamics.quaternion import attitude_error_vector_rad

#: The two-sided probability of the ANEES band.
BAND_LEVEL = 0.95
VERDICTS = ("consistent", "optimistic", "pessimistic")
#: A verdict within this fraction of the band's half-width from an edge is borderline.
BORDERLINE = 0.1


def anees_band(n_runs: int, dof: int, level: float = BAND_LEVEL) -> tuple[float, float]:
    """Two-sided ``level`` band of the average NEES of ``n_runs`` runs with
    ``dof``-dimensional errors: ``χ²(dof · N)`` quantiles divided by ``N``."""
    low, high = chi2.ppf([(1 - level) / 2, (1 + level) / 2], dof * n_runs)
    return float(low / n_runs), float(high / n_runs)


def verdict(anees_value: float, band: tuple[float, float]) -> str:
    """"consistent", "optimistic" (above the band) or "pessimistic" (below it),
    with " (borderline)" within :data:`BORDERLINE` of the band's half-width
    from an edge."""
    low, high = band
    margin = BORDERLINE * (high - low) / 2.0
    word = ("optimistic" if anees_value > high else "pessimistic" if anees_value < low
            else "consistent")
    near = min(abs(anees_value - low), abs(anees_value - high)) <= margin
    return f"{word} (borderline)" if near else word


# --- Campaigns: the engine where an estimator has a kernel, the per-run path otherwise ---

#: Runs of estimators without a kernel (users' own), unless asked for more:
#: each is a full per-run simulation, a thousand times slower than the engine.
PER_RUN_LIMIT = 20
#: NEES samples kept per run (the time series is decimated to about this many).
NEES_SAMPLES = 1000


@dataclass
class ConsistencyResult:
    """A consistency campaign: per estimator, its summary and its ANEES over time."""

    scenario: object
    time_s: np.ndarray                  # the sampled times of the ANEES series
    summary: dict                       # name → {runs, rms_deg, bound_rms_deg, …}
    anees: dict                         # name → (S,) ANEES at time_s, or None
    bound_rms_deg: np.ndarray           # (S,) the bound's RMS angle at time_s (posterior)
    bound: object                       # the AttitudeBound over the whole time grid
    samples: dict                       # name → TracedRun of the base seed's run
    diverged_step: dict | None = None   # name → (runs,) diverged steps, -1 where none
    settle_s: float = 0.0               # the start of every time average, seconds


@dataclass(frozen=True)
class TracedRun:
    """One run of one estimator as the per-axis figure shows it: its
    body-frame attitude error and, if it keeps a covariance, its 1σ per axis."""

    label: str
    time_s: np.ndarray                  # (N,)
    error_deg: np.ndarray               # (N, 3)
    sigma_deg: np.ndarray | None        # (N, 3), or None without a covariance


def traced_runs(scenario, estimators, seed: int) -> dict:
    """Each estimator's run of ``seed`` with its error and 1σ at every step
    (:func:`benchmarks.engine.runner.run_many` with its traces kept)."""
    from benchmarks.engine.batch import make_runs
    from benchmarks.engine.runner import run_many
    from benchmarks.sensor_use import tagged_label
    from benchmarks.simulation import build_estimator, simulate_truth
    truth = simulate_truth(scenario)
    batch = run_many(scenario, make_runs(scenario, [seed]), estimators, keep_traces=True)
    traced = {}
    for name in estimators:
        variances = batch.attitude_variances.get(name)
        traced[name] = TracedRun(
            label=tagged_label(build_estimator(name, scenario).label, batch.usage[name].note()),
            time_s=truth.time_s,
            error_deg=np.degrees(attitude_error_vector_rad(truth.q_true,
                                                           batch.estimates[name][0])),
            sigma_deg=None if variances is None else np.degrees(np.sqrt(variances[0])))
    return traced


def run_consistency(scenario, estimators, runs: int, base_seed: int = 0,
                    settle_s: float | None = None, per_run_limit: int = PER_RUN_LIMIT,
                    workers: int = 0, progress_bar=None,
                    level: float = BAND_LEVEL) -> ConsistencyResult:
    """Run ``runs`` seeds (``base_seed + i``) of each estimator and judge them.

    Estimators with an engine kernel run on the engine, streaming NEES;
    the others run per run (at most ``per_run_limit`` seeds), on a local Dask
    cluster of ``workers`` processes if asked (:func:`benchmarks.engine.runner.run_many`).
    ``settle_s`` (default a tenth of the run) is left out of the time averages.
    """
    from benchmarks.bounds import posterior_crb
    from benchmarks.engine.batch import make_runs, seed_range
    from benchmarks.engine.runner import run_many
    from benchmarks.simulation import build_estimator

    n_steps = scenario.n_steps
    every = max(1, n_steps // NEES_SAMPLES)
    settle_steps = round((scenario.tstop / 10 if settle_s is None else settle_s) / scenario.dt)
    settle_steps = min(max(settle_steps, 0), n_steps - 1)
    bound = posterior_crb(scenario)
    sample_every = error_sample_step(every, scenario)
    batch = run_many(scenario, make_runs(scenario, seed_range(base_seed, runs)), estimators,
                     per_run_limit=per_run_limit, consistency=True, nees_every=every,
                     settle_steps=settle_steps, error_every=sample_every, workers=workers,
                     progress_bar=progress_bar)
    # Each run's RMS from its errors sampled after the settle time; the bound
    # over every step after it (the sampling step shares no factor with the
    # readings' period, so the samples see every phase of it alike).
    first = -(-settle_steps // sample_every)
    per_run = {name: {"rms_deg": _rms(batch.error_samples[name][:, first:]),
                      "diverged_step": batch.diverged_step[name],
                      **batch.consistency.get(name, {})} for name in estimators}

    summary, anees = {}, {}
    for name in estimators:
        output = getattr(build_estimator(name, scenario), "output", "posterior")
        bound_rms = bound.rms_deg(output, start=settle_steps)
        summary[name], anees[name] = _summary_row(per_run[name], bound_rms, level)
        summary[name]["output"] = output
        summary[name]["note"] = batch.usage[name].note()
    # One traced run (the base seed) of each estimator for the per-axis figure.
    samples = traced_runs(scenario, estimators, base_seed)
    time_s = bound.time_s[::every]
    bound_rms = np.degrees(np.sqrt(np.trace(bound.posterior[::every], axis1=1, axis2=2)))
    return ConsistencyResult(scenario=scenario, time_s=time_s, summary=summary, anees=anees,
                             bound_rms_deg=bound_rms, bound=bound, samples=samples,
                             diverged_step={name: per_run[name]["diverged_step"]
                                            for name in estimators},
                             settle_s=settle_steps * scenario.dt)


def error_sample_step(every: int, scenario) -> int:
    """The step between the errors a campaign keeps: about ``every``, and
    sharing no factor with the steps between readings, so the samples fall on
    every phase of the reading cycle alike (a multiple of it would keep only
    the errors just after a reading, and understate the RMS)."""
    if not scenario.readings_on_gyro_grid:
        return every
    period = max(1, round(scenario.time_between_measurements / scenario.dt))
    step = max(1, every)
    while period > 1 and math.gcd(step, period) != 1:
        step += 1
    return step


def _rms(samples: np.ndarray) -> np.ndarray:
    """Each run's RMS over its sampled errors ``(runs, S)``: NaN where it diverged."""
    return np.sqrt(np.mean(samples * samples, axis=1))


def _summary_row(record: dict, bound_rms_deg: float, level: float) -> tuple[dict, object]:
    """One estimator's row of the table, and its ANEES over time (or None),
    from its per-run figures. Runs that diverged are counted and left out of
    every average; an estimator that diverged in any run is not consistent."""
    kept = record["diverged_step"] < 0
    n_runs, lost = int(kept.sum()), int((~kept).sum())
    row = {"runs": n_runs, "diverged": lost,
           "rms_deg": float(np.sqrt(np.mean(record["rms_deg"][kept] ** 2))) if n_runs
           else np.nan, "bound_rms_deg": bound_rms_deg}
    row["efficiency"] = row["rms_deg"] / row["bound_rms_deg"]
    row["band_level"] = level
    anees = None
    if "nees_samples" in record and n_runs:
        band = anees_band(n_runs, 3, level)
        row.update(anees=float(np.mean(record["nees_time_average"][kept])), anees_low=band[0],
                   anees_high=band[1])
        row["verdict"] = verdict(row["anees"], band)
        anees = record["nees_samples"][kept].mean(axis=0)
    else:
        row.update(anees=np.nan, anees_low=np.nan, anees_high=np.nan,
                   verdict="no covariance" if n_runs else "no run")
    if lost:
        row["verdict"] = f"diverged in {lost} of {n_runs + lost} runs"
    if "nis_mean" in record and n_runs:
        row["anis"] = float(np.mean(record["nis_mean"][kept]))
        row["nis_dof"] = record["nis_dof"]
    return row, anees


def table_unit(values_deg) -> tuple[str, float]:
    """One unit for a table of angles, by the magnitude of its median finite
    value (:func:`benchmarks.metrics.angle_unit`); ``(unit, scale from degrees)``."""
    finite = [v for v in values_deg if np.isfinite(v)]
    scale, unit = angle_unit(float(np.median(finite)) if finite else 1.0)
    return unit, scale


def format_summary(summary: dict, settle_s: float | None = None) -> str:
    """The printed table: estimator, runs, RMS error, bound, efficiency, ANEES, band,
    verdict; every angle in one unit, named in the header."""
    width = max(22, *(len(name) for name in summary))
    unit, scale = table_unit([row[key] for row in summary.values()
                              for key in ("rms_deg", "bound_rms_deg")])
    level = next((row.get("band_level") for row in summary.values()), None) or BAND_LEVEL
    header = (f"{'estimator':<{width}} {'runs':>5} {'rms ' + unit:>12} {'bound ' + unit:>12} "
              f"{'efficiency':>10} {'ANEES':>8} {f'{100 * level:.0f}% band':>15}  verdict")
    lines = [header]
    for name, row in summary.items():
        band = ("" if np.isnan(row["anees"]) else
                f"[{row['anees_low']:.2f}, {row['anees_high']:.2f}]")
        anees_text = "" if np.isnan(row["anees"]) else f"{row['anees']:.3g}"
        lines.append(f"{name:<{width}} {row['runs']:>5} {row['rms_deg'] * scale:>12.4g}"
                     f" {row['bound_rms_deg'] * scale:>12.4g} {row['efficiency']:>10.3f}"
                     f" {anees_text:>8} {band:>15}  {row['verdict']}")
    if settle_s is not None:
        lines.append(f"(RMS, bound and ANEES from t = {settle_s:g} s on; each bound before or "
                     "after the step's reading as its estimator outputs)")
    lines += [f"note: {name}: {row['note']}" for name, row in summary.items()
              if row.get("note")]
    return "\n".join(lines)


def consistency_frame(result: ConsistencyResult) -> pd.DataFrame:
    """Tidy: one row per (estimator, sampled time) with ANEES, its band, the
    bound's RMS angle, and the estimator's summary figures."""
    parts = []
    for name, row in result.summary.items():
        part = pd.DataFrame({"estimator": name, "time_s": result.time_s,
                             "anees": (result.anees[name] if result.anees[name] is not None
                                       else np.nan),
                             "anees_low": row["anees_low"], "anees_high": row["anees_high"],
                             "bound_rms_deg": result.bound_rms_deg, "runs": row["runs"],
                             "rms_deg": row["rms_deg"], "efficiency": row["efficiency"],
                             "anis": row.get("anis", np.nan), "verdict": row["verdict"]})
        parts.append(part)
    return pd.concat(parts, ignore_index=True)


def figure(result: ConsistencyResult):
    """The consistency figure of a campaign: each estimator's ANEES from its
    summary's runs, the settle time where its averages start, and one run's
    errors (see :func:`benchmarks.figures.consistency.consistency_figure`)."""
    from benchmarks.figures.consistency import consistency_figure
    errors, sigmas, labels, time_s = {}, {}, {}, None
    for name, sample in result.samples.items():
        labels[name] = sample.label
        time_s = sample.time_s
        if sample.sigma_deg is None:
            continue          # the per-axis panels are about envelopes
        errors[name] = sample.error_deg
        sigmas[name] = sample.sigma_deg
    bound_sigma = np.degrees(np.sqrt(np.diagonal(result.bound.posterior, axis1=1, axis2=2)))
    bands = {name: (row["anees_low"], row["anees_high"]) for name, row in result.summary.items()}
    from benchmarks.experiments.runs import reading_window
    runs = {name: row["runs"] for name, row in result.summary.items()}
    # The table's time averages and verdicts, so that the figure and the table agree.
    averages = {name: (row["anees"], row["verdict"]) for name, row in result.summary.items()
                if np.isfinite(row["anees"])}
    level = next(iter(result.summary.values()), {}).get("band_level", BAND_LEVEL)
    return consistency_figure(result.time_s, result.anees, bands, errors, sigmas, bound_sigma,
                              time_s, labels, runs=runs,
                              envelope_steps=reading_window(result.scenario), level=level,
                              settle_s=result.settle_s, averages=averages)
