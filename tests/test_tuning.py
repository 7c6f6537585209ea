"""Activity 3b: the fminbnd-style tuner and its iteration table."""
import contextlib
import io
import json
import re

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from benchmarks.cli import main
from benchmarks.scenario import Scenario
from benchmarks.experiments.tuning import (EkfLoss, format_iteration_table, minimize_bounded,
                                          tune_pc_exponent)

# scipy's own log of minimize_scalar(np.sin, bounds=(0, 2π), method="bounded",
# options={"disp": 3}), the fminbnd documentation's example (default xtol 1e-5).
SIN_LOG = """\
    1        2.39996      0.67549        initial
    2        3.88322     -0.67549        golden
    3        4.79993    -0.996171        golden
    4        5.08984    -0.929607        parabolic
    5        4.70582    -0.999978        parabolic
    6         4.7118           -1        parabolic
    7        4.71239           -1        parabolic
    8        4.71239           -1        parabolic
    9        4.71238           -1        parabolic"""


def scipy_log_rows(func, bounds, xtol):
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        minimize_scalar(func, bounds=bounds, method="bounded", options={"xatol": xtol, "disp": 3})
    pattern = re.compile(r"^\s*(\d+)\s+(\S+)\s+(\S+)\s+(initial|golden|parabolic)\s*$")
    return [m.groups() for m in map(pattern.match, text.getvalue().splitlines()) if m]


def test_iteration_table_of_sin_matches_scipys_log():
    log = minimize_bounded(np.sin, (0.0, 2 * np.pi), 1e-5)
    assert format_iteration_table(log.iterations).splitlines()[1:] == SIN_LOG.splitlines()
    assert log.x == pytest.approx(1.5 * np.pi, abs=1e-5)


@pytest.mark.parametrize("func, bounds, xtol", [
    (lambda x: (x - 0.3) ** 2 + 0.1 * np.cos(7 * x), (-2.0, 3.0), 1e-3),
    (lambda x: abs(x + 7.25) + 0.01 * x * x, (-16.0, 0.0), 0.01),
])
def test_counts_x_and_procedures_match_scipys_log(func, bounds, xtol):
    expected = scipy_log_rows(func, bounds, xtol)
    log = minimize_bounded(func, bounds, xtol)
    assert [row["count"] for row in log.iterations] == [int(e[0]) for e in expected]
    assert [row["procedure"] for row in log.iterations] == [e[3] for e in expected]
    assert [f"{row['x']:.6g}" for row in log.iterations] == [e[1] for e in expected]
    assert all(row["f"] == pytest.approx(func(row["x"])) for row in log.iterations)
    assert log.iterations[0]["procedure"] == "initial"
    assert "xtol" in log.message


class SyntheticLoss:
    """A loss with a known optimum per seed: optimum(seed) = -7.3 + 0.1 seed."""

    calls = 0

    def __init__(self, scenario, seeds):
        self.optimum = np.mean([-7.3 + 0.1 * s for s in seeds])

    def __call__(self, x):
        SyntheticLoss.calls += 1
        return (x - self.optimum) ** 2 + 0.5


def test_tune_finds_known_optimum_within_xtol():
    result = tune_pc_exponent(Scenario(), (0,), bounds=(-16, 0), xtol=0.01,
                              loss_factory=SyntheticLoss, quiet=True)
    assert abs(result.pc_exponent - -7.3) < 0.01
    assert result.loss_deg == pytest.approx(0.5, abs=1e-4)
    assert result.evaluations == len(result.iterations)
    assert result.single_seed_optima is None


def test_several_seeds_report_spread_of_single_seed_optima():
    seeds = tuple(range(20))
    result = tune_pc_exponent(Scenario(), seeds, xtol=0.001, loss_factory=SyntheticLoss,
                              quiet=True)
    optima = np.array([-7.3 + 0.1 * s for s in seeds])
    assert abs(result.pc_exponent - optima.mean()) < 0.001
    spread = result.single_seed_optima
    for key, q in (("p5", 5), ("p50", 50), ("p95", 95)):
        assert spread[key] == pytest.approx(np.percentile(optima, q), abs=0.002)


def test_tune_on_the_ekf_finds_the_minimum_of_its_loss(tmp_path, capsys):
    # Over 10 s the EKF's loss is least near pc = -12.6 (not the workshop's
    # -8.7, found over 50 s): the found exponent beats its neighbours half a
    # decade away and the search's two ends, each evaluated afresh.
    assert main(["tune", "--out", str(tmp_path), "--tstop", "10", "--quiet"]) == 0
    data = json.loads((tmp_path / "tune.json").read_text())
    assert set(data) >= {"pc_exponent", "loss_deg", "evaluations", "seeds", "iterations"}
    assert data["seeds"] == [0] and data["evaluations"] == len(data["iterations"])
    assert set(data["iterations"][0]) == {"count", "x", "f", "procedure"}
    assert min(row["f"] for row in data["iterations"]) == data["loss_deg"]
    assert -16 <= data["pc_exponent"] <= 0
    loss, found = EkfLoss(Scenario(tstop=10.0), (0,)), data["pc_exponent"]
    assert loss(found) == pytest.approx(data["loss_deg"], rel=1e-12)
    assert all(loss(found) < loss(other) for other in (found - 0.5, found + 0.5, -16.0, 0.0))
    assert (tmp_path / "tune.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "Func-count" in printed and "Procedure" in printed and "initial" in printed
    assert "Optimization terminated successfully" in printed


@pytest.mark.parametrize("argv, text", [
    (["--bounds", "0", "-16"], "bounds"),
    (["--bounds", "nan", "0"], "bounds"),
    (["--xtol", "0"], "xtol"),
    (["--seeds", "3-1"], "seeds"),
])
def test_bad_tune_options_fail_cleanly(tmp_path, capsys, argv, text):
    out = tmp_path / "out"
    assert main(["tune", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert text in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
