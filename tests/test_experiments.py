"""Sweeps, the landscape and the animations: files, rows and frames."""
import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from benchmarks import Scenario
from benchmarks.cli import main
from benchmarks.experiments.landscape import LANDSCAPE_COLUMNS, pc_grid

SHORT = ["--tstop", "1", "--quiet"]


def read_rows(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_sweep_rows_equal_one_run_per_value(tmp_path):
    values = ["-8.7", "-10.9", "-6"]
    assert main(["sweep", "--estimator", "ekf", "--param", "pc-exponent",
                 "--values", ",".join(values), "--seed", "2", "--out", str(tmp_path / "s"),
                 *SHORT]) == 0
    rows = read_rows(tmp_path / "s" / "sweep.csv")
    assert list(rows[0]) == ["param", "value", "mean_deg", "median_deg", "std_deg",
                             "three_sigma_deg", "rms_deg", "max_deg", "final_deg"]
    assert [float(r["value"]) for r in rows] == [float(v) for v in values]
    for value, row in zip(values, rows):
        out = tmp_path / f"run{value}"
        assert main(["run", "--estimator", "ekf", "--pc-exponent", value, "--seed", "2",
                     "--out", str(out), *SHORT]) == 0
        error = np.array([float(r["error_deg"]) for r in read_rows(out / "ekf.csv")])
        assert float(row["max_deg"]) == pytest.approx(error.max(), rel=1e-9)
        assert float(row["final_deg"]) == pytest.approx(error[-1], rel=1e-9)
        assert float(row["std_deg"]) == pytest.approx(np.std(error, ddof=1), rel=1e-9)
    assert Image.open(tmp_path / "s" / "sweep.png").size[0] > 500


@pytest.mark.parametrize("param, values, bad", [
    ("gyro-noise", "1e-5,-1", "gyro_noise"),
    ("time-between-measurements", "0.2,0.005", "time_between_measurements"),
    ("pc-exponent", "a,b", "values"),
])
def test_bad_sweep_values_fail_cleanly(tmp_path, capsys, param, values, bad):
    out = tmp_path / "out"
    assert main(["sweep", "--estimator", "ekf", "--param", param, "--values", values,
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert bad in err and len(err.splitlines()) == 1 and not out.exists()


def test_landscape_csv_png_gif(tmp_path):
    out = tmp_path / "l"
    assert main(["landscape", "--pc-min", "-10", "--pc-max", "-8", "--pc-step", "0.5",
                 "--seeds", "0-2", "--out", str(out), *SHORT]) == 0
    rows = read_rows(out / "landscape.csv")
    assert tuple(rows[0]) == LANDSCAPE_COLUMNS
    assert [float(r["pc_exponent"]) for r in rows] == [-10, -9.5, -9, -8.5, -8]
    assert all(r["runs"] == "3" for r in rows)
    runs = read_rows(out / "landscape_runs.csv")
    assert len(runs) == 15
    at_minus_9 = [float(r["std_deg"]) for r in runs if float(r["pc_exponent"]) == -9]
    assert float(rows[2]["std_deg"]) == pytest.approx(np.mean(at_minus_9), rel=1e-9)
    with Image.open(out / "landscape.gif") as gif:
        assert gif.n_frames == 5
    for name in ("landscape.png", "landscape_spread.png"):
        with Image.open(out / name) as image:
            image.verify()


def test_pc_grid_includes_both_ends():
    grid = pc_grid(-18, 0, 0.25)
    assert len(grid) == 73 and grid[0] == -18 and grid[-1] == pytest.approx(0)


@pytest.mark.parametrize("argv, name", [
    (["--pc-step", "0"], "pc_step"),
    (["--pc-min", "0", "--pc-max", "-1"], "pc_max"),
    (["--pc-step", "1e-9"], "pc_step"),
])
def test_bad_landscape_grid_fails_cleanly(tmp_path, capsys, argv, name):
    out = tmp_path / "out"
    assert main(["landscape", "--out", str(out), *argv]) == 2
    assert name in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("estimator, frames", [(None, 5),
                                               pytest.param("ekf", 5, marks=pytest.mark.slow)])
def test_attitude_animation_frames_and_still(tmp_path, estimator, frames):
    argv = ["animate", "--every", "25", "--out", str(tmp_path), *SHORT]
    if estimator:
        argv += ["--estimator", estimator]
    assert main(argv) == 0
    name = f"attitude_{estimator or 'truth'}"
    with Image.open(tmp_path / f"{name}.gif") as gif:
        assert gif.n_frames == frames       # steps 0, 25, 50, 75 and the last, 100
    with Image.open(tmp_path / f"{name}.png") as still:
        still.verify()


def test_animate_rejects_bad_every(tmp_path, capsys):
    assert main(["animate", "--every", "0", "--out", str(tmp_path / "o")]) == 2
    assert "every" in capsys.readouterr().err and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_workshop_writes_report_with_every_figure(tmp_path):
    assert main(["workshop", "--out", str(tmp_path), "--tstop", "1", "--quiet"]) == 0
    report = (tmp_path / "report.md").read_text()
    for heading in range(1, 10):
        assert f"## {heading}." in report
    linked = [line.split("](")[1].rstrip(")") for line in report.splitlines()
              if line.startswith("![")]
    assert len(linked) >= 11
    for relative in linked:
        assert (tmp_path / relative).is_file(), relative
    assert "Func-count" in report and "| ekf |" in report


@pytest.mark.slow      # a process of its own, importing everything: 8 s
def test_notebook_script_runs_as_plain_python(tmp_path):
    script = (Path(__file__).resolve().parents[1] / "benchmarks" / "experiments"
              / "workshop_notebook.py")
    assert script.read_text().count("# %%") >= 8
    # PYTHONPATH: the source tree's package, whose kernels the suite has
    # compiled (an installed copy would compile them again: 45 s).
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          env={"ATTITUDE_BENCH_TSTOP": "1", "ATTITUDE_BENCH_OUT": str(tmp_path),
                               "PATH": "", "MPLBACKEND": "Agg",
                               "PYTHONPATH": str(script.parents[2])}, cwd=tmp_path,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "pc_exponent =" in done.stdout
    assert (tmp_path / "compare.png").is_file() and (tmp_path / "landscape.png").is_file()


@pytest.mark.slow      # the whole report with its figures: 4 s
def test_flight_study_report_has_its_sections_figures_and_numbers(tmp_path, monkeypatch):
    from benchmarks.experiments import flight_study
    # The study's own sizes take about a minute; the same code on small ones.
    monkeypatch.setattr(flight_study, "STUDY_TSTOP_S", 30.0)
    monkeypatch.setattr(flight_study, "WORKSHOP_SEEDS", 8)
    monkeypatch.setattr(flight_study, "FLIGHT_ENGINE_RUNS", 10)
    monkeypatch.setattr(flight_study, "PC_GRID", np.array([-9.0, -8.5, -8.0]))
    assert main(["workshop", "--part", "flight", "--out", str(tmp_path), "--tstop", "5",
                 "--quiet"]) == 0
    report = (tmp_path / "report.md").read_text()
    for heading in ("## 1.", "## 2.", "## 3."):
        assert heading in report
    for linked in ("compare.png", "consistency.png"):
        assert (tmp_path / linked).is_file()
    # Every filter runs on the engine, USQUE included.
    assert "| mekf | 10 |" in report and "| usque | 10 |" in report
    assert "efficiency of" in report and "µs" in report


@pytest.mark.slow
def test_workshop_prose_follows_the_numbers_when_the_flags_change_them(tmp_path):
    # A gyro 1000x noisier and a loose Q: resets beat dead reckoning and the EKF.
    assert main(["workshop", "--out", str(tmp_path), "--tstop", "5", "--gyro-noise", "1e-2",
                 "--pc-exponent", "-3", "--quiet"]) == 0
    report = (tmp_path / "report.md").read_text()
    assert "times smaller than dead reckoning's" in report
    assert "Here dead-reckoning-resets, not the EKF, has the lowest mean error" in report
    assert "Q = exp(-3) I₄" in report
    # The exercise's values, shortened: over 5 s dead reckoning has not drifted
    # yet and is the best (the old fixed prose said the EKF); by 20 s the EKF is.
    for tstop, best in (("5", "Here dead-reckoning, not the EKF,"), ("20", "The EKF")):
        out = tmp_path / tstop
        assert main(["workshop", "--out", str(out), "--tstop", tstop, "--quiet"]) == 0
        report = (out / "report.md").read_text()
        assert f"{best} has the lowest mean error of the three" in report
        assert "circles the minor axis" in report


def test_the_tumble_is_described_from_energy_and_momentum():
    from benchmarks.experiments.workshop import tumble_description
    inertia = np.diag([1.0, 2.0, 3.0])
    assert "minor" in tumble_description(Scenario(inertia_tensor_kg_m2=inertia,
                                                  initial_rate_radps=[0.05, 0.05, 0.0]))
    assert "major" in tumble_description(Scenario(inertia_tensor_kg_m2=inertia,
                                                  initial_rate_radps=[0.0, 0.05, 0.05]))
    assert "spins steadily about the principal axis of 2" in tumble_description(
        Scenario(inertia_tensor_kg_m2=inertia, initial_rate_radps=[0.0, 0.05, 0.0]))


def test_flight_study_verdicts_follow_the_efficiencies():
    from benchmarks.experiments.flight_study import _mekf_text, _verdict
    assert "*is* the best filter" in _verdict(1.01, Scenario())
    assert "0.2 s reading interval" in _verdict(1.01, Scenario())
    assert "stays 30 % above" in _verdict(1.3, Scenario())
    assert _mekf_text(0.97).startswith("The MEKF sits at the bound (efficiency 0.97")
    assert _mekf_text(1.5) == "The MEKF is 1.50 times the bound"


# --- Any sweepable key of a scenario section ---

FLIGHT_SCENARIO_FILE = Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml"


def test_a_section_key_sweeps_in_its_own_units(tmp_path):
    from benchmarks.experiments import SWEEP_PARAMETERS, sweep, sweep_scenarios
    from sensors.noise import arw_deg_per_rthr_to_rad_per_rts
    flight = Scenario.from_toml(FLIGHT_SCENARIO_FILE).replace(tstop=20.0)
    assert {"gyro.arw_deg_per_rthr", "star_tracker.sigma_arcsec",
            "star_tracker.interval_s"} <= set(SWEEP_PARAMETERS)
    arw = sweep_scenarios(flight, "gyro.arw_deg_per_rthr", [0.01, 0.02])
    assert [case.gyro_noise for case in arw] == [arw_deg_per_rthr_to_rad_per_rts(v) ** 2
                                                 for v in (0.01, 0.02)]
    sigma = sweep_scenarios(flight, "star_tracker.sigma_arcsec", [3.0])[0]
    assert sigma.star_tracker_sigma_arcsec.tolist() == [3.0, 3.0, 3.0]   # a number: every axis
    rows = sweep(flight, "mekf", "star_tracker.sigma_arcsec", [2.0, 20.0], 0, tmp_path,
                 quiet=True)
    # Ten times the tracker's noise: the matched MEKF's error grows with it.
    assert rows[1]["rms_deg"] > 3 * rows[0]["rms_deg"]


def test_a_swept_key_the_model_does_not_read_is_refused(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "--estimator", "mekf", "--param", "star_tracker.sigma_arcsec",
                 "--values", "1,2", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no effect with the workshop star tracker" in err and err.count("\n") == 1
    assert not out.exists()
