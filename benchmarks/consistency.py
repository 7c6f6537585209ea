r"""Consistency: does a filter know its own error?

For an estimate with error :math:`e_k` (here the body-frame small angle
:math:`\delta\theta`, 3 components, or the bias error) and the covariance
:math:`P_k` the filter reports for it, the normalised estimation error squared

.. math:: \epsilon_k = e_k^\mathsf{T} P_k^{-1} e_k

is :math:`\chi^2(n)` distributed with :math:`n` the error's dimension if the
filter is consistent (its errors zero-mean with covariance :math:`P_k`).
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
single-time band is a conservative band for the time average.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import chi2

from dynamics.quaternion import attitude_error_vector_rad

#: The two-sided probability of the ANEES band.
BAND_LEVEL = 0.95
VERDICTS = ("consistent", "optimistic", "pessimistic")


def nees(errors: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """``eᵀ P⁻¹ e`` for stacks of errors ``(..., n)`` and covariances ``(..., n, n)``."""
    errors = np.asarray(errors, dtype=float)
    solved = np.linalg.solve(np.asarray(covariances, dtype=float), errors[..., None])[..., 0]
    return np.sum(errors * solved, axis=-1)


def anees_band(n_runs: int, dof: int, level: float = BAND_LEVEL) -> tuple[float, float]:
    """Two-sided ``level`` band of the average NEES of ``n_runs`` runs with
    ``dof``-dimensional errors: ``χ²(dof · N)`` quantiles divided by ``N``."""
    low, high = chi2.ppf([(1 - level) / 2, (1 + level) / 2], dof * n_runs)
    return float(low / n_runs), float(high / n_runs)


def verdict(anees_value: float, band: tuple[float, float]) -> str:
    """"consistent", "optimistic" (above the band) or "pessimistic" (below it)."""
    if anees_value > band[1]:
        return "optimistic"
    if anees_value < band[0]:
        return "pessimistic"
    return "consistent"


def fraction_inside_3sigma(errors: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """Per axis, the fraction of samples with ``|e_i| <= 3 √P_ii`` (0.9973 if Gaussian)."""
    sigma = np.sqrt(np.diagonal(covariances, axis1=-2, axis2=-1))
    return np.mean(np.abs(errors) <= 3 * sigma, axis=tuple(range(np.ndim(errors) - 1)))


def run_errors(result, name: str) -> dict:
    """One run's attitude and bias errors of estimator ``name`` with the
    filter's covariances (from a :func:`~benchmarks.simulation.simulate` run
    with ``traces=True``); None entries where the estimator keeps none."""
    trace = result.traces[name]
    attitude = attitude_error_vector_rad(result.truth.q_true, trace.quat)
    bias = (None if trace.bias_radps is None
            else trace.bias_radps - result.sensors.gyro_bias_radps)
    return {"attitude": attitude, "attitude_covariance": trace.attitude_covariance,
            "bias": bias, "bias_covariance": trace.bias_covariance,
            "nis": trace.nis, "nis_dof": trace.nis_dof}


def monte_carlo(results, name: str, settle_steps: int = 0, level: float = BAND_LEVEL) -> dict:
    """Consistency of ``name`` over runs ``results`` (each simulated with traces).

    Returns ANEES over time (attitude, and bias where estimated), its band,
    ANIS over time at reading steps, the time-averaged figures from
    ``settle_steps`` on, each axis's fraction inside ±3σ, and the verdict.
    None for an estimator that reports no covariance.
    """
    runs = [run_errors(result, name) for result in results]
    if runs[0]["attitude_covariance"] is None:
        return None
    n_runs = len(runs)
    attitude_nees = np.array([nees(r["attitude"], r["attitude_covariance"]) for r in runs])
    summary = {"runs": n_runs, "anees": attitude_nees.mean(axis=0),
               "band": anees_band(n_runs, 3, level)}
    summary["anees_time_average"] = float(summary["anees"][settle_steps:].mean())
    summary["verdict"] = verdict(summary["anees_time_average"], summary["band"])
    errors = np.array([r["attitude"][settle_steps:] for r in runs])
    covariances = np.array([r["attitude_covariance"][settle_steps:] for r in runs])
    summary["inside_3sigma"] = fraction_inside_3sigma(errors, covariances)
    if runs[0]["bias"] is not None:
        bias_nees = np.array([nees(r["bias"], r["bias_covariance"]) for r in runs])
        summary["bias_anees"] = bias_nees.mean(axis=0)
        summary["bias_anees_time_average"] = float(summary["bias_anees"][settle_steps:].mean())
    if runs[0]["nis"] is not None:
        nis = np.array([r["nis"] for r in runs])
        summary["anis"] = nis.mean(axis=0)
        summary["nis_dof"] = runs[0]["nis_dof"]
        summary["nis_band"] = anees_band(n_runs, runs[0]["nis_dof"], level)
        kept = nis[:, settle_steps:]
        summary["anis_time_average"] = float(np.nanmean(kept))
    return summary


def tidy_frame(time_s: np.ndarray, summaries: dict) -> pd.DataFrame:
    """One row per (estimator, time): ANEES with its band, and ANIS where read."""
    parts = []
    for name, summary in summaries.items():
        if summary is None:
            continue
        part = pd.DataFrame({"estimator": name, "time_s": time_s, "anees": summary["anees"],
                             "anees_low": summary["band"][0], "anees_high": summary["band"][1],
                             "runs": summary["runs"]})
        if "anis" in summary:
            part["anis"] = summary["anis"]
        if "bias_anees" in summary:
            part["bias_anees"] = summary["bias_anees"]
        parts.append(part)
    return pd.concat(parts, ignore_index=True)
