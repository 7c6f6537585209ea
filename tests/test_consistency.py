"""Consistency statistics: they pass a correct filter and catch a mistuned one."""
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from benchmarks.experiments.consistency import anees_band, verdict
from benchmarks.metrics import nees

N_RUNS = 50
STEPS = 200
DT = 0.1
Q_SPECTRAL = 0.5      # white-acceleration density of the toy's truth


def toy_runs(q_scale):
    """A constant-velocity target measured in position: N runs of the truth
    (which follows the model exactly) and a filterpy KalmanFilter whose Q is
    ``q_scale`` times the truth's. Returns NEES (N, steps) of the 2-D state."""
    F = np.array([[1.0, DT], [0.0, 1.0]])
    Q = Q_SPECTRAL * np.array([[DT ** 3 / 3, DT ** 2 / 2], [DT ** 2 / 2, DT]])
    R = np.array([[0.04]])
    rng = np.random.default_rng(20261122)
    out = np.empty((N_RUNS, STEPS))
    for run in range(N_RUNS):
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.F, kf.Q, kf.R, kf.H = F, q_scale * Q, R, np.array([[1.0, 0.0]])
        kf.x = np.zeros(2)
        kf.P = np.eye(2)
        truth = rng.multivariate_normal(np.zeros(2), np.eye(2))
        for k in range(STEPS):
            truth = F @ truth + rng.multivariate_normal(np.zeros(2), Q)
            kf.predict()
            kf.update(truth[:1] + rng.normal(0, 0.2, 1))
            out[run, k] = nees(truth - kf.x, kf.P)
    return out


def test_nees_of_a_correct_linear_gaussian_filter_is_inside_its_band():
    # A consistent filter's ANEES at each time is χ²(2N)/N; the time average
    # of those has the same mean and no larger a variance: the 95 % band.
    anees = toy_runs(1.0).mean(axis=0)
    band = anees_band(N_RUNS, 2)
    assert verdict(anees.mean(), band) == "consistent"
    # And most single times are inside too (95 % expected; 85 % allowed, a
    # binomial bound far below what 200 correlated samples could produce by chance).
    assert np.mean((anees > band[0]) & (anees < band[1])) > 0.85


def test_nees_catches_a_filter_whose_q_is_ten_times_too_small():
    anees = toy_runs(0.1).mean(axis=0)
    band = anees_band(N_RUNS, 2)
    assert verdict(anees[20:].mean(), band) == "optimistic"
    assert anees[20:].mean() > 1.5 * band[1]


def test_band_is_the_chi_square_quantile_over_n():
    low, high = anees_band(10, 3, level=0.99)
    assert (low, high) == pytest.approx((chi2.ppf(0.005, 30) / 10, chi2.ppf(0.995, 30) / 10))
    assert verdict(3.0, (low, high)) == "consistent"
    assert verdict(high * 1.5, (low, high)) == "optimistic"
    assert verdict(low * 0.5, (low, high)) == "pessimistic"


def test_a_verdict_near_its_band_edge_says_borderline():
    # Within BORDERLINE (10 %) of the band's half-width from an edge, either side.
    low, high = 2.5, 3.5                      # half-width 0.5: a margin of 0.05
    assert verdict(3.46, (low, high)) == "consistent (borderline)"
    assert verdict(3.54, (low, high)) == "optimistic (borderline)"
    assert verdict(2.47, (low, high)) == "pessimistic (borderline)"
    assert verdict(3.44, (low, high)) == "consistent"
    assert verdict(3.56, (low, high)) == "optimistic"


@pytest.mark.slow
def test_consistency_command_prints_the_table_and_writes_csv_and_figure(tmp_path, capsys):
    from benchmarks.cli import main
    short = tmp_path / "short.toml"
    flight = (__import__("pathlib").Path(__file__).resolve().parents[1] / "scenarios"
              / "flight.toml").read_text()
    short.write_text(flight.replace("tstop = 3600.0", "tstop = 60.0"))
    out = tmp_path / "out"
    assert main(["consistency", "--scenario", str(short), "--runs", "30", "--per-run-limit", "2",
                 "--settle", "10", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    for name in ("dead-reckoning", "ekf", "mekf", "usque"):
        assert name in printed
    assert "no covariance" in printed and "efficiency" in printed
    import pandas as pd
    frame = pd.read_csv(out / "consistency.csv")
    assert set(frame["estimator"]) == {"dead-reckoning", "dead-reckoning-resets", "ekf", "mekf",
                                       "usque"}
    mekf = frame[frame["estimator"] == "mekf"]
    # Every built-in estimator runs on the engine, so the per-run limit bites
    # none of them (it limits users' own: tests/test_byo.py).
    assert (mekf["runs"] == 30).all() and (frame["runs"] == 30).all()
    # Its band is χ²(3·30)/30's at 99 % (it holds 3 by construction), and the
    # flight MEKF's ANEES lies in it (measured 2.64 in [2.19, 3.94]).
    row = mekf.iloc[0]
    assert row["anees_low"] < 3 < row["anees_high"]
    assert row["anees_low"] < row["anees"] < row["anees_high"] and row["verdict"] == "consistent"
    assert (out / "consistency.png").stat().st_size > 10_000


@pytest.mark.parametrize("argv, text", [
    (["--runs", "0"], "runs = '0'"),
    (["--settle", "-1"], "settle = -1.0"),
    (["--estimators", "ekf,kalman"], "estimators = 'ekf,kalman'"),
])
def test_bad_consistency_input_fails_cleanly(tmp_path, capsys, argv, text):
    from benchmarks.cli import main
    assert main(["consistency", "--out", str(tmp_path / "x"), *argv]) == 2
    err = capsys.readouterr().err
    assert text in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()
