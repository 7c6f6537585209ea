"""Never a silently wrong number: diverged runs, foreign chunks, malformed
engine input, and the command line's answers to them."""
import math
import shutil
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks import Scenario, simulate
from benchmarks.cli import main
from benchmarks.divergence import EXIT_DIVERGED
from benchmarks.engine import RunTable, make_runs, run_batch, run_many
from benchmarks.engine.campaign import MANIFEST, Campaign, chunk_path, run_campaign
from benchmarks.experiments.tuning import EkfLoss, tune_pc_exponent
from benchmarks.metrics import STAT_COLUMNS, error_statistics
from dynamics.validation import MAX_SEED, InvalidParameterError
from estimators import DeadReckoning
from estimators.base import InvalidMeasurementError


SHORT = Scenario(tstop=2.0)
#: e^709 is finite, but the EKF's covariance overflows within two steps.
DIVERGING_PC = 709.0


def one_diverging_table(n_runs=5, bad=2):
    pc = np.full(n_runs, SHORT.pc_exponent)
    pc[bad] = DIVERGING_PC
    return make_runs(SHORT, np.arange(n_runs), pc_exponent=pc)


def test_one_diverged_run_of_n_is_counted_nan_and_the_rest_are_right():
    batch = run_batch(SHORT, one_diverging_table(), ["dead-reckoning", "ekf"])
    steps = batch.diverged_step["ekf"]
    assert (steps >= 0).tolist() == [False, False, True, False, False]
    assert (batch.diverged_step["dead-reckoning"] == -1).all()
    for column in STAT_COLUMNS:
        assert math.isnan(batch.statistics["ekf"][column][2])       # never 0
    healthy = run_batch(SHORT, make_runs(SHORT, [0, 1, 3, 4]), ["ekf"]).statistics["ekf"]
    for column in STAT_COLUMNS:
        np.testing.assert_array_equal(batch.statistics["ekf"][column][[0, 1, 3, 4]],
                                      healthy[column])


def test_both_paths_give_the_same_verdict_at_the_same_step():
    batch = run_batch(SHORT, one_diverging_table(), ["ekf"], keep_traces=True)
    for seed in range(5):
        pc = DIVERGING_PC if seed == 2 else SHORT.pc_exponent
        result = simulate(SHORT.replace(pc_exponent=pc), ["ekf"], seed=seed)
        assert result.diverged_step["ekf"] == batch.diverged_step["ekf"][seed]
        engine = batch.estimates["ekf"][seed]
        np.testing.assert_allclose(result.estimates["ekf"], engine, atol=1e-9, rtol=0)
        assert np.array_equal(np.isnan(result.estimates["ekf"]), np.isnan(engine))
        stats = error_statistics(result.error_deg["ekf"])
        for column in STAT_COLUMNS:
            np.testing.assert_allclose(stats[column], batch.statistics["ekf"][column][seed],
                                       rtol=1e-6, atol=1e-9)    # NaN equals NaN here
    assert batch.diverged_step["ekf"][2] == 0      # trace(e^709 I) overflows at once


def test_usque_diverges_at_the_same_step_on_both_paths():
    # σ_v² = 1e307 in the filter: Q drives P to overflow, and the update at
    # the second reading (step 20) finds no Cholesky factor on either path.
    # (A covariance that loses definiteness by rounding, P − K S Kᵀ with
    # P ≫ R, may tip either way: the paths sum in different orders.)
    scenario = SHORT.replace(estimator_options={"usque": {"gyro_noise": 1e307}})
    batch = run_batch(scenario, make_runs(scenario, [0, 1]), ["usque", "mekf"],
                      keep_traces=True)
    assert batch.diverged_step["usque"].tolist() == [20, 20]
    assert batch.diverged_step["mekf"].tolist() == [-1, -1]
    for seed in (0, 1):
        result = simulate(scenario, ["usque"], seed=seed)
        assert result.diverged_step["usque"] == 20
        engine = batch.estimates["usque"][seed]
        assert np.array_equal(np.isnan(result.estimates["usque"]), np.isnan(engine))
        np.testing.assert_allclose(result.estimates["usque"], engine, atol=1e-9, rtol=0)
    assert math.isnan(batch.statistics["usque"]["rms_deg"][0])


def test_consistency_streams_nan_for_a_diverged_run_and_counts_it():
    from benchmarks.experiments.consistency import _summary_row
    batch = run_batch(SHORT, one_diverging_table(), ["ekf"], consistency=True)
    record = batch.consistency["ekf"]
    assert np.isnan(record["nees_time_average"][2]) and np.isnan(record["nis_mean"][2])
    assert np.isfinite(np.delete(record["nees_time_average"], 2)).all()
    row, anees = _summary_row({"rms_deg": batch.statistics["ekf"]["rms_deg"],
                               "diverged_step": batch.diverged_step["ekf"],
                               **{key: record[key] for key in ("nees_samples",
                                                               "nees_time_average",
                                                               "nis_mean", "nis_dof")}},
                              bound_rms_deg=1.0, level=0.95)
    assert row["runs"] == 4 and row["diverged"] == 1
    assert row["verdict"] == "diverged in 1 of 5 runs"
    assert np.isfinite(row["rms_deg"]) and np.isfinite(anees).all()


def test_montecarlo_exits_non_zero_on_divergence_unless_allowed(tmp_path, capsys):
    argv = ["montecarlo", "--estimators", "dead-reckoning,ekf", "--runs", "3", "--tstop", "1",
            "--pc-exponent", "709", "--quiet"]
    assert main(argv + ["--out", str(tmp_path / "a")]) == EXIT_DIVERGED
    err = capsys.readouterr().err
    assert "ekf diverged in 3 of 3 runs (first at step 0, t = 0 s)" in err
    assert "--allow-divergence" in err and "Traceback" not in err
    lines = (tmp_path / "a" / "montecarlo.csv").read_text().splitlines()
    ekf = [line.split(",") for line in lines if ",ekf," in line]
    assert len(ekf) == 3 and all(row[3] == "nan" and row[-1] == "0" for row in ekf)
    assert main(argv + ["--out", str(tmp_path / "b"), "--allow-divergence"]) == 0


def test_per_run_commands_report_divergence(tmp_path, capsys):
    assert main(["compare", "--pc-exponent", "709", "--tstop", "1", "--quiet",
                 "--out", str(tmp_path / "c")]) == EXIT_DIVERGED
    captured = capsys.readouterr()
    assert "ekf diverged in 1 of 1 runs" in captured.err
    assert "nan" in captured.out.splitlines()[-2]            # the ekf row of the table
    assert main(["consistency", "--estimators", "ekf,mekf", "--runs", "2", "--tstop", "1",
                 "--pc-exponent", "709", "--quiet", "--out", str(tmp_path / "k")]) \
        == EXIT_DIVERGED
    table = capsys.readouterr().out
    assert "diverged in 2 of 2 runs" in table and "consistent" in table   # the MEKF's row


def test_the_tuner_counts_a_diverged_candidate_as_an_infinite_loss():
    assert EkfLoss(SHORT, (0,))(DIVERGING_PC) == math.inf
    assert math.isfinite(EkfLoss(SHORT, (0,))(-8.7))
    # Up to about 705.7 the EKF runs (it follows the tracker); above, P = Σ e^pc overflows.
    result = tune_pc_exponent(SHORT, (0,), bounds=(700.0, 709.0), quiet=True)
    diverged = [row for row in result.iterations if row["f"] == math.inf]
    assert result.diverged_evaluations == len(diverged) >= 1
    assert all(row["x"] > 705.0 for row in diverged)
    assert math.isfinite(result.loss_deg)
    assert result.pc_exponent < min(row["x"] for row in diverged)
    assert EkfLoss(SHORT, (0,))(result.pc_exponent) == result.loss_deg
    assert all(row["f"] is None for row in result.as_json()["iterations"]
               if row["x"] in {d["x"] for d in diverged})


def test_a_step_that_raises_linalgerror_marks_divergence():
    class Breaks(DeadReckoning):
        def _step(self, omega, reading=None):
            if self.step_index == 4:
                raise np.linalg.LinAlgError("not positive definite")
            return super()._step(omega, reading)

    estimates = Breaks(dt=0.01).run(np.zeros((8, 3)), np.tile([1.0, 0, 0, 0], (8, 1)),
                                    np.zeros(8, dtype=bool))
    assert np.isfinite(estimates[:3]).all() and np.isnan(estimates[3:]).all()


# --- Campaigns know their own chunks ---

def _campaign(**changes):
    fields = dict(scenario=Scenario(tstop=1.0), estimators=("ekf",), runs=4, base_seed=0,
                  chunk_runs=2)
    fields.update(changes)
    return Campaign(**fields)


@pytest.mark.parametrize("other, what", [
    (dict(base_seed=10), "other settings"),
    (dict(scenario=Scenario(tstop=1.0, gyro_noise=2e-5)), "other settings")])
def test_resume_refuses_a_chunk_of_another_campaign(tmp_path, other, what):
    mine, theirs = tmp_path / "mine", tmp_path / "theirs"
    run_campaign(_campaign(), mine)
    run_campaign(_campaign(**other), theirs)
    shutil.copy(chunk_path(theirs, 0, 2), chunk_path(mine, 0, 2))
    with pytest.raises(InvalidParameterError, match=rf"runs-000000000-000000002.npz belongs "
                                                    rf"to another campaign \({what}\)"):
        run_campaign(_campaign(), mine, resume=True)


def test_resume_refuses_a_chunk_with_the_wrong_seeds(tmp_path):
    run_campaign(_campaign(), tmp_path)
    # The second chunk renamed as the first: same fingerprint, other seeds.
    shutil.copy(chunk_path(tmp_path, 2, 4), chunk_path(tmp_path, 0, 2))
    with pytest.raises(InvalidParameterError, match=r"\(other seeds\)"):
        run_campaign(_campaign(), tmp_path, resume=True)


def test_a_refused_campaign_leaves_no_manifest(tmp_path, monkeypatch):
    import benchmarks.engine.campaign as campaign_module

    def refuse(*args):
        raise InvalidParameterError("gyro_noise", 1, "refused during the run")
    monkeypatch.setattr(campaign_module, "compute_chunk", refuse)
    with pytest.raises(InvalidParameterError):
        run_campaign(_campaign(), tmp_path / "a")
    assert not (tmp_path / "a" / MANIFEST).exists()
    monkeypatch.undo()
    run_campaign(_campaign(), tmp_path / "a")       # the corrected rerun is accepted
    with pytest.raises(InvalidParameterError, match="runs"):
        run_campaign(_campaign(runs=0), tmp_path / "b")
    assert not (tmp_path / "b").exists()


def test_the_last_seed_is_exact(tmp_path):
    out = tmp_path / "mc"
    assert main(["montecarlo", "--estimators", "ekf", "--runs", "1", "--seed", str(MAX_SEED),
                 "--tstop", "0.5", "--quiet", "--out", str(out)]) == 0
    assert (out / "montecarlo.csv").read_text().splitlines()[1].split(",")[1] == str(MAX_SEED)


# --- The engine's public API checks its arguments ---

def test_unequal_columns_raise_valueerror_without_crashing_the_process():
    code = """
import numpy as np
from benchmarks import Scenario
from benchmarks.engine import RunTable, run_batch
scenario = Scenario(tstop=0.5)
runs = RunTable(np.arange(3), np.full(1, 1e-5), np.full(3, 1e-6), np.full(5, 0.2),
                np.full(3, -8.7))
try:
    run_batch(scenario, runs, ["ekf", "mekf"])
except ValueError as err:
    print("ValueError:", err)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "ValueError: runs = " in done.stdout and "same length" in done.stdout


@pytest.mark.parametrize("call, name", [
    (lambda: run_batch(SHORT, RunTable(*[np.array([])] * 5), ["ekf"]), "runs"),
    (lambda: run_batch(SHORT, make_runs(SHORT, [0]), "ekf"), "estimators"),
    (lambda: run_batch(SHORT, make_runs(SHORT, [0]), []), "estimators"),
    (lambda: run_batch(SHORT, make_runs(SHORT, [0]), ["ekf"], block_steps=0), "block_steps"),
    (lambda: run_many(SHORT, make_runs(SHORT, [0]), ["ekf"], chunk_runs=0), "chunk_runs"),
    (lambda: run_batch(SHORT, [0, 1], ["ekf"]), "runs"),
    (lambda: run_batch(SHORT, RunTable(np.arange(2), np.array([1e-5, np.nan]),
                                       np.full(2, 1e-6), np.full(2, 0.2), np.full(2, -8.7)),
                       ["ekf"]), "gyro_noise"),
])
def test_bad_engine_arguments_name_themselves(call, name):
    with pytest.raises(ValueError, match=rf"^{name}"):
        call()


_COLUMN = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=0, max_size=3)
    .map(np.array),
    st.lists(st.integers(-3, 3), min_size=0, max_size=3).map(np.array),
    st.lists(st.booleans(), min_size=1, max_size=3).map(np.array),
    st.lists(st.text(max_size=2), min_size=1, max_size=2).map(np.array),
    st.lists(st.complex_numbers(max_magnitude=1), min_size=1, max_size=2).map(np.array),
    st.just(np.zeros((2, 2))))


def _same_statistics(scenario, table: RunTable, columns) -> None:
    """``table`` runs as the validated constructor's table of ``columns``."""
    batch = run_batch(scenario, table, ["dead-reckoning", "ekf"])
    reference = run_batch(scenario, make_runs(scenario, columns[0], **dict(zip(
        ("gyro_noise", "star_tracker_noise", "time_between_measurements", "pc_exponent"),
        columns[1:]))), ["dead-reckoning", "ekf"])
    for name in batch.estimators:
        for column in STAT_COLUMNS:
            np.testing.assert_array_equal(batch.statistics[name][column],
                                          reference.statistics[name][column])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(columns=st.tuples(_COLUMN, _COLUMN, _COLUMN, _COLUMN, _COLUMN))
def test_random_malformed_tables_give_a_valueerror_or_the_right_answer(columns):
    """Property: whatever the table, the engine refuses it with a ValueError
    naming the runs (their lengths, or the column and its rule) or computes
    what the validated constructor's table computes (nearly every drawn
    table is refused: the next property draws valid ones)."""
    scenario = Scenario(tstop=0.05)
    try:
        run_batch(scenario, RunTable(*columns), ["dead-reckoning", "ekf"])
    except ValueError as error:
        assert str(error).startswith("runs"), error
        return
    _same_statistics(scenario, RunTable(*columns), columns)


@st.composite
def _valid_columns(draw):
    """Five columns of one length, each within its rule."""
    n = draw(st.integers(1, 3))
    def column(elements):
        return np.array(draw(st.lists(elements, min_size=n, max_size=n)))
    return (column(st.integers(0, 2 ** 31)), column(st.floats(1e-8, 1e-4)),
            column(st.floats(1e-8, 1e-5)), column(st.sampled_from([0.01, 0.02, 0.05])),
            column(st.floats(-12.0, -4.0)))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(columns=_valid_columns())
def test_a_valid_table_built_by_hand_runs_as_the_constructors(columns):
    _same_statistics(Scenario(tstop=0.05), RunTable(*columns), columns)


# --- The Python API validates at its door ---

def test_records_of_mismatched_lengths_are_refused_by_name():
    estimator = DeadReckoning(dt=0.01)
    star, flags = np.tile([1.0, 0, 0, 0], (5, 1)), np.zeros(5, dtype=bool)
    with pytest.raises(InvalidMeasurementError, match=r"^star_tracker_quat of shape = \(5, 4\)"):
        estimator.run(np.zeros((6, 3)), star, np.zeros(6, dtype=bool))
    with pytest.raises(InvalidMeasurementError, match=r"^available of shape = \(7,\)"):
        estimator.track(np.zeros((5, 3)), star, np.zeros(7, dtype=bool))
    with pytest.raises(InvalidMeasurementError, match="must be booleans"):
        estimator.run(np.zeros((5, 3)), star, np.zeros(5))
    with pytest.raises(InvalidMeasurementError, match="must be real numbers"):
        estimator.run(np.zeros((5, 3)) + 1j, star, flags)


def test_an_absurd_finite_rate_is_refused_at_its_step_or_skipped():
    rates = np.zeros((5, 3))
    rates[3] = [1e300, 0.0, 0.0]
    star, flags = np.tile([1.0, 0, 0, 0], (5, 1)), np.zeros(5, dtype=bool)
    with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps at step 3 .*1000"):
        DeadReckoning(dt=0.01).run(rates, star, flags)
    skipping = DeadReckoning(dt=0.01, on_invalid="skip")
    estimates = skipping.run(rates, star, flags)
    assert skipping.skipped["rate"] == 1 and np.isfinite(estimates).all()
    assert skipping.diverged_step is None


# --- Command-line input that used to be refused wrongly, or accepted wrongly ---

def test_overrides_are_checked_together(tmp_path):
    assert main(["run", "--estimator", "dead-reckoning", "--tstop", "0.001", "--dt", "1e-4",
                 "--quiet", "--out", str(tmp_path)]) == 0


@pytest.mark.parametrize("argv, first_line", [
    (["sweep", "--estimator", "dead-reckoning", "--param", "star-tracker-noise",
      "--values", "1e-6,1e-5"], "param = 'star-tracker-noise': has no effect on dead-reckoning"),
    (["compare", "--estimators", "dead-reckoning,mekf", "--pc-exponent", "-5"],
     "pc_exponent = -5.0: has no effect on dead-reckoning, mekf; it is read only by ekf"),
    (["compare", "--scenario", "scenarios/flight.toml", "--star-tracker-noise", "1e-5"],
     "star_tracker_noise = 1e-05: has no effect with the rotation star tracker"),
    (["consistency", "--star-tracker-noise", "0", "--runs", "2"],
     "star_tracker_noise = 0.0: must be > 0 on every axis for the bound"),
    (["workshop", "--star-tracker-noise", "0"],
     "star_tracker_noise = 0.0: must be > 0 on every axis for the bound"),
    (["montecarlo", "--chunk-size", "100000000"], "chunk_size = 100000000: a chunk of"),
    # Found by the audit: overflows that were tracebacks, values that were dropped.
    (["run", "--estimator", "ekf", "--time-between-measurements", "1e308"],
     "star_tracker.interval_s (time_between_measurements) = 1e+308: must be at most 1e+12 steps"),
    (["replay", "--star-tracker-interval", "1e308"], "star_tracker_interval = 1e+308: must be "
     "shorter than the recording"),
    (["replay", "--star-tracker-noise-deg", "1e308"], "star_tracker_noise_deg = 1e+308: must "
     "be at most 90°"),
    (["compare", "--star-tracker-noise", "1e308"], "star_tracker_noise = 1e+308: makes the "
     "reading noise"),
    (["tune", "--bounds", "0", "710"], "bounds = 710.0: must be <= 709"),
    (["sweep", "--estimator", "ekf", "--param", "pc-exponent", "--values", "-8,-9",
      "--pc-exponent", "-9"], "pc_exponent = -9.0: the sweep sets it"),
    (["sweep", "--estimator", "ekf", "--param", "pc-exponent", "--values", "-8,nan"],
     "pc_exponent = nan: must be finite"),
    (["landscape", "--pc-step", "1e308"], "pc_step = 1e+308: must be at most pc_max - pc_min"),
    (["montecarlo", "--scheduler", ""], "scheduler = '': must be an address"),
    (["compare", "--out", ""], "argument --out: out = '': must name a folder"),
])
def test_refusals_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, argv,
                                                 first_line):
    from pathlib import Path
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    out = tmp_path / "o"
    assert main(argv + ["--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"attitude-bench: error: {first_line}") and err.count("\n") == 1
    assert not out.exists()


def test_a_scenario_file_imports_a_module_only_with_consent(tmp_path, monkeypatch, capsys):
    """The module writes a marker file when imported: without consent it must not be."""
    marker = tmp_path / "imported.txt"
    (tmp_path / "noisyfilters.py").write_text(
        f"open({str(marker)!r}, 'w').write('ran')\n"
        "from estimators import DeadReckoning\n"
        "class Mine(DeadReckoning):\n    name = 'noisyfilters:Mine'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    scenario = tmp_path / "s.toml"
    scenario.write_text('tstop = 1.0\n[estimators."noisyfilters:Mine"]\nrate_timing = '
                        '"step-average"\n')
    argv = ["compare", "--scenario", str(scenario), "--quiet"]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 2
    assert "--allow-import noisyfilters" in capsys.readouterr().err
    assert not marker.exists() and "noisyfilters" not in sys.modules
    assert main(argv + ["--out", str(tmp_path / "b"), "--allow-import", "noisyfilters"]) == 0
    assert marker.exists()


@pytest.mark.parametrize("change, rule", [
    ({"sampling_rate_hz": np.array(1e-300)}, "sampling_rate_hz = 1e-300 must be within 0.01"),
    ({"sampling_rate_hz": np.array(1e308)}, "sampling_rate_hz = 1e+308 must be within 0.01"),
    ({"imu_gyr_radps": "huge"}, "imu_gyr_radps must be within ±1000 rad/s"),
])
def test_recordings_beyond_what_an_estimator_takes_are_refused(tmp_path, capsys, change, rule):
    from benchmarks.shipped import shipped_file
    with np.load(shipped_file("datasets/broad/02_undisturbed_slow_rotation_B.npz")) as data:
        arrays = dict(data)
    for key, value in change.items():
        if value == "huge":
            value = arrays[key].copy()
            value[5] = [1e300, 0.0, 0.0]
        arrays[key] = value
    np.savez(tmp_path / "r.npz", **arrays)
    assert main(["replay", "--dataset", str(tmp_path / "r.npz"), "--quiet",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert rule in err and err.count("\n") == 1 and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_animate_and_workshop_report_divergence(tmp_path, capsys):
    assert main(["animate", "--estimator", "ekf", "--pc-exponent", "709", "--tstop", "1",
                 "--quiet", "--out", str(tmp_path / "a")]) == EXIT_DIVERGED
    assert (tmp_path / "a" / "attitude_ekf.gif").exists()      # the truth, the estimate gone
    assert "ekf diverged in 1 of 1 runs" in capsys.readouterr().err
    assert main(["workshop", "--pc-exponent", "709", "--tstop", "2", "--quiet",
                 "--out", str(tmp_path / "w")]) == EXIT_DIVERGED
    assert "ekf diverged" in capsys.readouterr().err
    report = (tmp_path / "w" / "report.md").read_text()
    assert "(ekf diverged: no error to rank)" in report


@pytest.mark.slow      # the flight study with its figures: 3 s
def test_the_flight_study_reports_divergence(tmp_path, capsys, monkeypatch):
    from benchmarks.experiments import flight_study
    # The study's own sizes take about a minute; the same code on small ones,
    # with a USQUE whose σ_v² = 1e307 overflows its covariance (see above).
    monkeypatch.setattr(flight_study, "STUDY_TSTOP_S", 5.0)
    monkeypatch.setattr(flight_study, "WORKSHOP_SEEDS", 4)
    monkeypatch.setattr(flight_study, "FLIGHT_ENGINE_RUNS", 3)
    monkeypatch.setattr(flight_study, "PC_GRID", np.array([-9.0, -8.5]))
    shipped = flight_study.study_scenario
    monkeypatch.setattr(flight_study, "study_scenario", lambda: shipped().replace(
        estimator_options={**shipped().estimator_options, "usque": {"gyro_noise": 1e307}}))
    assert main(["workshop", "--part", "flight", "--tstop", "2", "--quiet",
                 "--out", str(tmp_path / "f")]) == EXIT_DIVERGED
    err = capsys.readouterr().err
    assert "usque diverged in 3 of 3 runs" in err and "mekf diverged" not in err


def test_resume_refuses_a_chunk_of_a_campaign_with_other_estimators(tmp_path):
    mine, theirs = tmp_path / "mine", tmp_path / "theirs"
    run_campaign(_campaign(estimators=("dead-reckoning", "ekf")), mine)
    run_campaign(_campaign(), theirs)                   # ekf alone: fewer columns
    shutil.copy(chunk_path(theirs, 0, 2), chunk_path(mine, 0, 2))
    with pytest.raises(InvalidParameterError, match="belongs to another campaign"):
        run_campaign(_campaign(estimators=("dead-reckoning", "ekf")), mine, resume=True)
    assert chunk_path(mine, 0, 2).exists()              # somebody's result: not deleted


def test_skipped_readings_have_no_nis_and_bad_seeds_name_themselves():
    from estimators import MultiplicativeEKF, QuaternionEKF
    star = np.tile([1.0, 0, 0, 0], (6, 1))
    star[2] = 0.0                                      # a zero-norm reading, skipped
    flags = np.ones(6, dtype=bool)
    for cls in (QuaternionEKF, MultiplicativeEKF):
        trace = cls(dt=0.01, on_invalid="skip").track(np.zeros((6, 3)), star, flags)
        assert np.isnan(trace.nis[2]) and np.isfinite(np.delete(trace.nis, 2)).all()
    with pytest.raises(InvalidParameterError, match=r"^seed"):
        make_runs(SHORT, [-1])
    with pytest.raises(InvalidParameterError, match=r"^seed"):
        simulate(SHORT, ["ekf"], seed=-1)
    with pytest.raises(InvalidParameterError, match=r"^estimators = 'ekf'"):
        simulate(SHORT, "ekf")
