"""The attitude-bench command line: outputs, and bad input rejected cleanly."""
import csv
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.experiments import TRACE_COLUMNS
from benchmarks.metrics import STAT_COLUMNS

SHORT = ["--tstop", "2"]


def read_csv(path):
    with open(path, newline="") as handle:
        return list(csv.reader(handle))


def test_run_writes_trace_csv_and_figure(tmp_path, capsys):
    assert main(["run", "--estimator", "ekf", "--out", str(tmp_path), *SHORT]) == 0
    rows = read_csv(tmp_path / "ekf.csv")
    assert tuple(rows[0]) == TRACE_COLUMNS
    assert len(rows) == 1 + 201
    data = np.array(rows[1:], dtype=float)
    assert np.allclose(data[:, 0], np.arange(201) * 0.01)
    assert np.allclose(np.linalg.norm(data[:, 1:5], axis=1), 1.0, atol=1e-11)
    assert (tmp_path / "ekf.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    line = capsys.readouterr().out.strip()
    assert line.startswith("ekf: mean ") and "std" in line and "max" in line and "final" in line


def test_compare_writes_summary_of_three_estimators(tmp_path):
    assert main(["compare", "--out", str(tmp_path), "--seed", "3", *SHORT]) == 0
    rows = read_csv(tmp_path / "summary.csv")
    assert tuple(rows[0]) == ("estimator",) + STAT_COLUMNS + ("note",)
    assert [r[0] for r in rows[1:]] == ["dead-reckoning", "dead-reckoning-resets", "ekf"]
    assert [r[-1] for r in rows[1:]] == ["", "", ""]      # every number the plain error
    values = np.array([r[1:-1] for r in rows[1:]], dtype=float)
    assert np.allclose(values[:, 3], 3 * values[:, 2], rtol=1e-9)     # 3σ column
    assert (tmp_path / "compare.png").stat().st_size > 10_000


def test_same_seed_same_files(tmp_path):
    for name in ("a", "b"):
        assert main(["run", "--estimator", "dead-reckoning-resets", "--seed", "5",
                     "--out", str(tmp_path / name), *SHORT]) == 0
    assert (tmp_path / "a" / "dead-reckoning-resets.csv").read_bytes() == \
        (tmp_path / "b" / "dead-reckoning-resets.csv").read_bytes()


def test_scenario_file_and_flag_override(tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text("tstop = 1.0\ngyro_noise = 0.0\nstar_tracker_noise = 0.0\n")
    out = tmp_path / "out"
    assert main(["run", "--estimator", "dead-reckoning", "--scenario", str(scenario),
                 "--tstop", "0.5", "--out", str(out)]) == 0
    rows = read_csv(out / "dead-reckoning.csv")
    assert len(rows) == 1 + 51
    assert max(float(r[-1]) for r in rows[1:]) < 0.05     # noiseless: first-order error only


BAD_FLAGS = [
    (["--gyro-noise", "nan"], "gyro_noise"),
    (["--gyro-noise", "inf"], "gyro_noise"),
    (["--gyro-noise", "-1e-5"], "gyro_noise"),
    (["--star-tracker-noise", "-1"], "star_tracker_noise"),
    (["--star-tracker-noise", "abc"], "--star-tracker-noise"),
    (["--dt", "0"], "dt"),
    (["--dt", "-0.01"], "dt"),
    (["--tstop", "0.001"], "tstop"),
    (["--time-between-measurements", "0.005"], "time_between_measurements"),
    (["--time-between-measurements", "0"], "time_between_measurements"),
    (["--pc-exponent", "nan"], "pc_exponent"),
    (["--seed", "-1"], "seed"),
    (["--seed", "1.5"], "seed"),
    (["--scenario", "does-not-exist.toml"], "scenario"),
]

BAD_FILES = [
    ("inertia_tensor_kg_m2 = [[1.0, 0.2, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]",
     "inertia_tensor_kg_m2", "symmetric"),
    ("inertia_tensor_kg_m2 = [1.0, 2.0, -3.0]", "inertia_tensor_kg_m2", "positive definite"),
    ("inertia_tensor_kg_m2 = [1.0, 1.0, 3.0]", "inertia_tensor_kg_m2", "triangle"),
    ("initial_attitude_quat = [0.0, 0.0, 0.0, 0.0]", "initial_attitude_quat", "non-zero"),
    ("initial_rate_radps = [0.05, 0.05]", "initial_rate_radps", "3 numbers"),
    ("gyro_noise = ", "scenario", "valid TOML"),
    ("gyro_nosie = 1e-5", "gyro_nosie", "not a scenario setting"),
    ("dt = 0.01\ntime_between_measurements = 0.004", "time_between_measurements",
     "must be >= the gyro's dt"),
]


def assert_clean_failure(capsys, out_dir, argv, *expected):
    assert main(argv) == 2
    captured = capsys.readouterr()
    message = captured.err.strip()
    assert captured.out == ""
    assert len(message.splitlines()) == 1, message
    assert message.startswith("attitude-bench: error: ")
    for text in expected:
        assert text in message, message
    assert not out_dir.exists()


@pytest.mark.parametrize("flags, name", BAD_FLAGS)
@pytest.mark.parametrize("command", ["run", "compare"])
def test_bad_flag_fails_cleanly(tmp_path, capsys, command, flags, name):
    out = tmp_path / "out"
    extra = ["--estimator", "ekf"] if command == "run" else []
    assert_clean_failure(capsys, out, [command, *extra, "--out", str(out), *flags], name)


@pytest.mark.parametrize("content, name, rule", BAD_FILES)
def test_bad_scenario_file_fails_cleanly(tmp_path, capsys, content, name, rule):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(content + "\n")
    out = tmp_path / "out"
    assert_clean_failure(capsys, out, ["compare", "--scenario", str(scenario),
                                       "--out", str(out)], name, rule)


def test_unknown_estimator_fails_cleanly(tmp_path, capsys):
    out = tmp_path / "out"
    assert_clean_failure(capsys, out, ["run", "--estimator", "ukf", "--out", str(out)],
                         "--estimator", "'ukf'", "dead-reckoning")


def test_console_script_exit_status_and_no_traceback(tmp_path):
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "benchmarks", "run", "--estimator", "ekf",
                           "--gyro-noise", "-1", "--out", str(out)],
                          capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == ("attitude-bench: error: gyro_noise = -1.0: must be >= 0 "
                                   "(from --gyro-noise)")
    assert "Traceback" not in done.stderr and not out.exists()


def test_outputs_are_readable_by_others(tmp_path):
    import os
    import stat
    old = os.umask(0o022)
    try:
        assert main(["compare", "--out", str(tmp_path), *SHORT]) == 0
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "summary.csv").stat().st_mode)
    assert mode == 0o644
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temp files left


@pytest.mark.slow
def test_flight_compare_draws_the_per_axis_figure_with_any_estimators(tmp_path, capsys):
    scenario = tmp_path / "short.toml"
    flight = (Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml").read_text()
    scenario.write_text(flight.replace("tstop = 3600.0", "tstop = 30.0"))
    out = tmp_path / "out"
    assert main(["compare", "--scenario", str(scenario), "--estimators",
                 "dead-reckoning,ekf,mekf", "--out", str(out), "--quiet"]) == 0
    rows = read_csv(out / "summary.csv")
    assert [row[0] for row in rows[1:]] == ["dead-reckoning", "ekf", "mekf"]
    # The per-axis figure is wider than the workshop's single panel.
    from PIL import Image
    with Image.open(out / "compare.png") as image:
        assert image.size[0] > 1500
    with Image.open(out / "compare.png") as image, \
            Image.open(Path(__file__).resolve().parents[1] / "docs" / "compare.png") as workshop:
        assert image.size != workshop.size


def test_compare_rejects_unknown_and_accepts_registry_names(tmp_path, capsys):
    assert main(["compare", "--estimators", "ekf,ukf", "--out", str(tmp_path / "x")]) == 2
    assert "estimators = 'ekf,ukf'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal, as tqdm asks before drawing a bar."""

    def isatty(self):
        return True


@pytest.mark.parametrize("argv, bar", [
    (["run", "--estimator", "mekf", "--tstop", "2"], "mekf:"),
    (["compare", "--tstop", "2"], "compare:"),
    pytest.param(["convergence", "--tstop", "2", "--seeds", "0", "--angles", "90"],
                 "convergence:", marks=pytest.mark.slow),    # 4 s
])
def test_long_commands_draw_a_progress_bar_on_a_terminal_and_none_when_quiet(
        tmp_path, monkeypatch, argv, bar):
    for quiet in (False, True):
        terminal = _Terminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        out = tmp_path / str(quiet)
        assert main([*argv, "--out", str(out), *(["--quiet"] if quiet else [])]) == 0
        assert (bar in terminal.getvalue()) is not quiet, terminal.getvalue()
