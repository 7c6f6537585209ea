"""The BROAD benchmark: the loader on every published format, the authors'
metric on constructed cases, the complementary filters against the
authors' published numbers, the peers, and bad input.

Tests marked ``full_broad`` need the full dataset (``ATTITUDE_BENCH_BROAD``,
which ``.ci/run`` points at it); elsewhere they are skipped, with the reason.
"""
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from benchmarks.broad import case_study
from benchmarks.broad.dataset import ENVIRONMENT_VARIABLE, broad_folder, open_broad
from benchmarks.broad.inputs import imu_inputs
from benchmarks.broad.metric import errors_deg, rmse_deg
from benchmarks.cli import main
from benchmarks.shipped import shipped_file
from dynamics.quaternion import quat_from_rotvec, quat_multiply, rotation_matrix
from estimators import MultiplicativeEKF, resolve_estimator
from sensors.vector import VectorObservation

#: The shipped subset itself (broad_folder(None) is the full set where it is set).
SHIPPED = shipped_file("datasets/broad/trials.json").parent
FULL = os.environ.get(ENVIRONMENT_VARIABLE)
full_broad = pytest.mark.skipif(not FULL, reason=f"needs the full BROAD dataset: set "
                                f"{ENVIRONMENT_VARIABLE} (.ci/run does)")


def test_without_a_folder_the_environment_variable_or_the_shipped_subset_is_read(monkeypatch):
    monkeypatch.delenv(ENVIRONMENT_VARIABLE, raising=False)
    assert broad_folder(None) == SHIPPED
    monkeypatch.setenv(ENVIRONMENT_VARIABLE, "/somewhere/broad")
    assert broad_folder(None) == Path("/somewhere/broad")


def test_the_shipped_subset_is_a_broad_folder_with_both_vector_channels():
    dataset = open_broad(SHIPPED)
    assert dataset.available == ["02_undisturbed_slow_rotation_B",
                                 "07_undisturbed_fast_rotation_B"]
    recording = dataset.load(dataset.trial_name("2"))
    assert recording.accelerometer_mps2.shape == recording.magnetometer_uT.shape == (53240, 3)
    # At rest the specific force is gravity, up: 9.8 m/s² along the body's near-vertical z.
    rest = recording.accelerometer_mps2[recording.rest_samples].mean(axis=0)
    assert 9.7 < np.linalg.norm(rest) < 9.9 and rest[2] > 9.7
    assert dataset.members("rotation") == dataset.available
    assert dataset.members("translation") == []


def test_an_hdf5_trial_written_from_a_shipped_one_loads_identically(tmp_path):
    h5py = pytest.importorskip("h5py")
    shipped = open_broad(SHIPPED)
    name = "02_undisturbed_slow_rotation_B"
    source = shipped.load(name)
    (tmp_path / "data_hdf5").mkdir()
    shutil.copy(SHIPPED / "trials.json", tmp_path / "trials.json")
    with h5py.File(tmp_path / "data_hdf5" / f"{name}.hdf5", "w") as file:
        file["imu_gyr"] = source.gyro_radps
        file["imu_acc"] = source.accelerometer_mps2
        file["imu_mag"] = source.magnetometer_uT
        file["opt_quat"] = source.reference_quat
        file["movement"] = source.movement.astype(np.uint8)[:, None]
        file["sampling_rate"] = np.array([[source.rate_hz]])
    loaded = open_broad(tmp_path).load(name)
    for field in ("gyro_radps", "accelerometer_mps2", "magnetometer_uT", "reference_quat",
                  "movement"):
        assert np.array_equal(getattr(loaded, field), getattr(source, field), equal_nan=True)
    assert loaded.rate_hz == source.rate_hz


@full_broad
def test_the_published_mat_files_load_as_the_shipped_npz_hold_them():
    full = open_broad(FULL)
    assert len(full.available) >= 30
    for name in open_broad(SHIPPED).available:
        mat, npz = full.load(name), open_broad(SHIPPED).load(name)
        for field in ("gyro_radps", "accelerometer_mps2", "magnetometer_uT", "reference_quat"):
            assert np.array_equal(getattr(mat, field), getattr(npz, field), equal_nan=True)


# --- the metric ------------------------------------------------------------------

@settings(max_examples=50, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-3, 3))
def test_a_heading_error_is_no_inclination_error_and_a_tilt_no_heading_error(
        heading, tilt_x, tilt_y, yaw):
    # The error is taken in the earth frame: a rotation about the vertical,
    # applied on the earth side of any reference, is heading alone.
    reference = quat_from_rotvec(np.array([tilt_x, tilt_y, yaw]))[None]
    turned = quat_multiply(quat_from_rotvec(np.array([0.0, 0.0, heading])), reference[0])[None]
    found = errors_deg(turned, reference)
    # (2 arccos resolves angles to about √(8 ε) rad, 2e-6°: the tolerances are 1e-5°.)
    assert found["heading"][0] == pytest.approx(abs(math.degrees(heading)), abs=1e-5)
    assert found["inclination"][0] == pytest.approx(0.0, abs=1e-5)
    assert found["total"][0] == pytest.approx(abs(math.degrees(heading)), abs=1e-5)
    tilt = np.array([tilt_x, tilt_y, 0.0])
    tilted = quat_multiply(quat_from_rotvec(tilt), reference[0])[None]
    found = errors_deg(tilted, reference)
    assert found["heading"][0] == pytest.approx(0.0, abs=1e-5)
    assert found["inclination"][0] == pytest.approx(math.degrees(np.linalg.norm(tilt)),
                                                    abs=1e-5)


def test_the_rmse_is_over_the_movement_samples_with_a_reference():
    reference = np.tile([1.0, 0.0, 0.0, 0.0], (4, 1))
    estimate = np.array([quat_from_rotvec(np.radians([0.0, 0.0, a])) for a in (9, 3, 4, 50)])
    reference[2] = np.nan                                # a gap in the reference
    movement = np.array([False, True, True, True])
    found = rmse_deg(estimate, reference, movement)
    assert found["total_rmse_deg"] == pytest.approx(math.sqrt((3 ** 2 + 50 ** 2) / 2))
    assert found["inclination_rmse_deg"] == pytest.approx(0.0, abs=1e-6)


def test_a_diverged_estimate_scores_nan_not_the_mean_of_what_is_left():
    # The reference's gaps are left out; an estimate's NaN (a filter that
    # diverged) is not a gap: a mean over the steps before it would flatter it.
    reference = np.tile([1.0, 0.0, 0.0, 0.0], (4, 1))
    estimate = np.array([quat_from_rotvec(np.radians([0.0, 0.0, 2.0]))] * 4)
    estimate[3] = np.nan
    found = rmse_deg(estimate, reference, np.ones(4, dtype=bool))
    assert all(math.isnan(value) for value in found.values())
    reference[3] = np.nan                     # now that sample is not scored
    assert rmse_deg(estimate, reference, np.ones(4, dtype=bool))["total_rmse_deg"] == \
        pytest.approx(2.0)


# --- the estimators on 9-D data --------------------------------------------------

#: The BROAD authors' published values at their chosen settings (Madgwick's
#: C code with β = 0.12; Mahony Kp = 0.74, Ki = 0.0012): total, heading and
#: inclination RMSE in degrees, from the dataset's case_study/
#: results_madgwick_average_rmse.json and results_mahony_average_rmse.json
#: (dlaidig/broad, example_code/out). The tolerance, 1e-3°, covers their
#: filters' single precision (our double-precision port differs by < 1e-4°).
PUBLISHED = {
    ("02", "madgwick-broad"): (1.4968208029725296, 1.2637374170489573, 0.8021668950285171),
    ("07", "madgwick-broad"): (4.996321474071987, 4.326588111600188, 2.4993232473704006),
    ("02", "mahony"): (2.966195102266719, 2.8908935782635035, 0.6641901191459872),
    ("07", "mahony"): (5.232809160286603, 4.898510580751595, 1.8408920189096445),
}


@pytest.mark.parametrize("trial, name", [
    ("02", "madgwick-broad"), ("02", "mahony"),
    pytest.param("07", "madgwick-broad", marks=pytest.mark.slow),
    pytest.param("07", "mahony", marks=pytest.mark.slow)])
def test_the_authors_filters_reproduce_their_published_errors(trial, name):
    dataset = open_broad(SHIPPED)
    trial_name = dataset.trial_name(trial)
    frame = case_study.reproduce(dataset, [trial_name], {}, quiet=True)
    ours = frame[frame["estimator"] == name].set_index("metric")["ours"]
    total, heading, inclination = PUBLISHED[(trial, name)]
    assert ours["total_rmse_deg"] == pytest.approx(total, abs=1e-3)
    assert ours["heading_rmse_deg"] == pytest.approx(heading, abs=1e-3)
    assert ours["inclination_rmse_deg"] == pytest.approx(inclination, abs=1e-3)


def test_madgwick_without_the_slip_is_another_filter():
    # The halved field reference (the dataset's issue #1) changes the
    # gradient: on one step from the same state the two filters differ.
    q0 = case_study.authors_initial_state(np.array([0.1, 0.2, 9.8]), np.array([20.0, 5, -40]))
    steps = {}
    for name in ("madgwick", "madgwick-broad"):
        estimator = resolve_estimator(name)(dt=0.01, initial_attitude=q0, beta=0.5)
        vectors = (VectorObservation(np.array([1.0, 0.5, 9.7]), np.array([0, 0, 9.8]), 1.0,
                                     "accelerometer"),
                   VectorObservation(np.array([10.0, 15, -38]), np.array([0, 20, -40.0]), 1.0,
                                     "magnetometer"))
        steps[name] = estimator.step(np.zeros(3), None, vectors=vectors)
    assert not np.allclose(steps["madgwick"], steps["madgwick-broad"], atol=1e-6)


@pytest.mark.parametrize("sensor, reference", [
    ("accelerometer", np.array([0.0, 0.0, 9.82])),
    ("magnetometer", np.array([0.0, 15.6, -40.9]))])
def test_the_mekf_gravity_and_field_jacobians_match_finite_differences(rng, sensor, reference):
    mekf = MultiplicativeEKF(dt=0.0035, initial_attitude=rng.standard_normal(4))
    _, H = mekf.vector_model(VectorObservation(np.zeros(3), reference, 1.0, sensor))
    q, step = mekf.q_hat, 1e-6
    numeric = np.column_stack([
        (rotation_matrix(quat_multiply(q, quat_from_rotvec(step * e))).T @ reference
         - rotation_matrix(quat_multiply(q, quat_from_rotvec(-step * e))).T @ reference)
        / (2 * step) for e in np.eye(3)])
    assert np.allclose(H[:, :3], numeric, rtol=1e-7, atol=1e-9 * np.abs(reference).max())


def test_the_rest_gives_the_references_and_a_start_near_the_reference():
    dataset = open_broad(SHIPPED)
    inputs = imu_inputs(dataset.load(dataset.trial_name("02")))
    field = inputs.references["magnetometer"]
    dip = math.degrees(math.atan2(-field[2], field[1]))
    assert 60.0 < dip < 75.0                  # Berlin's inclination is about 68°
    recording = inputs.recording
    first = recording.reference_quat[np.argmax(recording.has_reference)]
    assert errors_deg(inputs.scenario.initial_state[None], first[None])["total"][0] < 6.0


def test_vqf_is_told_its_magnetometers_rate_where_it_reads_slower():
    """VQF's magTs sets its magnetometer filters' coefficients: a logger's
    magnetometer at a quarter of the gyro's rate (with a dropout that
    lengthens one interval, which the median ignores) is told to it, else its
    heading correction is four times too slow; one read with every sample is
    told nothing (BROAD's trials, whose VQF numbers then stay as published)."""
    from dataclasses import replace
    from sensors.recording import reading_interval_s
    dataset = open_broad(SHIPPED)
    recording = dataset.load(dataset.trial_name("02"))
    assert "vqf" not in imu_inputs(recording).scenario.estimator_options
    field = recording.magnetometer_uT.copy()
    read = np.arange(len(field)) % 4 == 0
    read[400] = False
    field[~read] = 0.0                         # the dataset's mark of no reading
    slower = imu_inputs(replace(recording, magnetometer_uT=field))
    options = slower.scenario.estimator_options["vqf"]
    assert options["magnetometer_interval_s"] == pytest.approx(4 * recording.dt, rel=1e-12)
    assert "accelerometer_interval_s" not in options
    assert "vqf" not in slower.scenario.estimator_options.get("vqf-offline", {})
    # An accelerometer read at half the gyro's rate: its accTs too, for both VQFs.
    force = recording.accelerometer_mps2.copy()
    force[np.arange(len(force)) % 2 == 1] = 0.0
    both = imu_inputs(replace(recording, magnetometer_uT=field, accelerometer_mps2=force))
    for name in ("vqf", "vqf-6d"):
        told = both.scenario.estimator_options[name]
        assert told["accelerometer_interval_s"] == pytest.approx(2 * recording.dt, rel=1e-12)
        assert told["magnetometer_interval_s"] == pytest.approx(4 * recording.dt, rel=1e-12)
    assert reading_interval_s(np.array([True, False, False]), 0.01) == 0.01


def _slower_channels(name: str, every: dict, **options):
    """Estimator ``name`` on 30 s of trial 02's movement whose channels read
    every ``every[sensor]`` samples: at once and sample by sample (both
    asserted equal to the bit), and on every sample; and the recording."""
    from dataclasses import replace
    dataset = open_broad(SHIPPED)
    recording = dataset.load(dataset.trial_name("02")).from_sample(11000).until_sample(3000)
    inputs = imu_inputs(recording)
    vectors = tuple(replace(v, available=v.available & (np.arange(len(v.available))
                                                        % every.get(v.sensor, 1) == 0))
                    for v in inputs.sensors.vectors)
    estimator = resolve_estimator(name).from_scenario(inputs.scenario, **options)
    s = inputs.sensors
    batch = estimator.run_batch(s.omega_meas_radps, vectors)
    assert batch is not None
    stepped = estimator.run(s.omega_meas_radps, s.star_tracker_quat, s.available,
                            vectors=vectors)
    np.testing.assert_array_equal(batch, stepped)
    whole = estimator.run(s.omega_meas_radps, s.star_tracker_quat, s.available,
                          vectors=s.vectors)
    return stepped, whole, recording


def test_vqf_runs_at_once_on_a_magnetometer_that_reads_slower():
    """VQF skips a [0, 0, 0] reading (vqf.cpp's updateAcc and updateMag), so
    a magnetometer at a quarter of the gyro's rate runs through its batch
    update, zeros where it did not read, as through its sample-by-sample
    calls without them: the same estimates to the bit (it took the per-sample
    path, 40 µs a sample against 0.5)."""
    pytest.importorskip("vqf")
    _slower_channels("vqf", {"magnetometer": 4}, magnetometer_interval_s=0.04)


def test_fusion_holds_a_slower_channels_last_reading():
    """Fusion takes every channel at every sample: where the accelerometer
    and the magnetometer read slower (here a half and a quarter of the
    gyro's rate), each is held from its last reading, the same at once as
    sample by sample, and the gyro is integrated at every sample (a sample
    without an accelerometer reading was skipped, its rate lost: the
    estimate then turned half as fast as the body)."""
    pytest.importorskip("imufusion")
    stepped, whole, recording = _slower_channels("fusion", {"accelerometer": 2,
                                                           "magnetometer": 4})
    slow, full = (rmse_deg(q, recording.reference_quat, recording.movement)["total_rmse_deg"]
                  for q in (stepped, whole))
    assert slow < 2 * full + 1.0, (slow, full)


@pytest.mark.parametrize("name", ["vqf", pytest.param("fusion", marks=pytest.mark.slow)])
def test_the_peers_run_as_registry_estimators(name, tmp_path):
    pytest.importorskip({"vqf": "vqf", "fusion": "imufusion"}[name])
    dataset = open_broad(SHIPPED)
    recording = dataset.load(dataset.trial_name("02")).from_sample(11000)
    inputs = imu_inputs(recording)
    estimator = resolve_estimator(name).from_scenario(inputs.scenario)
    s = inputs.sensors
    estimate = estimator.run(s.omega_meas_radps, s.star_tracker_quat, s.available,
                             vectors=s.vectors)
    # Over the first 20 s of the movement both peers stay within a few degrees
    # of the reference (a frame convention mistake would show as 90° or 180°).
    scored = recording.movement.copy()
    scored[int(20 * recording.rate_hz):] = False
    assert rmse_deg(estimate, recording.reference_quat, scored)["total_rmse_deg"] < 8.0


@full_broad
@pytest.mark.slow
def test_the_gate_rejects_the_attached_magnets_disturbed_field():
    # Trial 32 (a magnet 1 cm from the IMU) against trial 02 (undisturbed):
    # the workshop's EKF, reading the field as a vector behind its 99.99 %
    # gate, rejects far more magnetometer readings. (The MEKF's and USQUE's
    # heading model takes the magnet's constant field as a new reference
    # after 20 s: tests/test_imu_models.py.)
    from benchmarks.broad.benchmark import run_trial
    full = open_broad(FULL)
    counts = {}
    for trial in ("02", "32"):
        rows, _, _ = run_trial(full, full.trial_name(trial), ["ekf"])
        counts[trial] = rows[0]["rejected_magnetometer"]
    assert counts["32"] > 5 * max(counts["02"], 1000)


# --- the command -----------------------------------------------------------------

def test_the_broad_command_writes_its_tables_and_figures(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(SHIPPED), "--trials", "02", "--estimators", "madgwick,dead-reckoning",
                 "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "all_trials (1)" in printed and "CC BY 4.0" in printed
    for name in ("broad_trials.csv", "broad_groups.csv", "broad.png", "broad_trial.png",
                 "ATTRIBUTION.txt"):
        assert (out / name).is_file()
    import pandas as pd
    groups = pd.read_csv(out / "broad_groups.csv")
    madgwick = groups[(groups.group == "rotation") & (groups.estimator == "madgwick")]
    assert 1.0 < float(madgwick["total_rmse_deg"].iloc[0]) < 2.5


def _broken_folder(tmp_path, change):
    """A copy of the shipped folder with one trial, changed by ``change(arrays)``."""
    folder = tmp_path / "broken"
    folder.mkdir()
    shutil.copy(SHIPPED / "trials.json", folder / "trials.json")
    name = "02_undisturbed_slow_rotation_B"
    arrays = dict(np.load(SHIPPED / f"{name}.npz"))
    change(arrays)
    np.savez(folder / f"{name}.npz", **arrays)
    return folder


@pytest.mark.parametrize("make, argv, message", [
    (lambda tmp: tmp, [], "has no trials.json"),
    (lambda tmp: _broken_folder(tmp, lambda a: a.pop("movement")), [], "has no key 'movement'"),
    (lambda tmp: _broken_folder(tmp, lambda a: a.update(imu_acc_mps2=a["imu_acc_mps2"][:-5])),
     [], "imu_acc_mps2 has shape (53235, 3); must be (53240, 3)"),
    (lambda tmp: _broken_folder(tmp, lambda a: a.pop("imu_acc_mps2")), [],
     "has no imu_acc channel; the IMU filters scored here need the accelerometer at least"),
    (lambda tmp: SHIPPED, ["--trials", "99"], "trials = '99': is not a trial of"),
    (lambda tmp: SHIPPED, ["--gyro-delay", "1"], "gyro_delay = 1.0: must be within ±50 samples"),
    (lambda tmp: SHIPPED, ["--case-study", "--gyro-delay", "0.003"],
     "--gyro-delay does not apply to --case-study"),
    (lambda tmp: SHIPPED, ["--case-study", "--agreement"],
     "--agreement does not apply to --case-study"),
    (lambda tmp: SHIPPED, ["--case-study"], "--estimators does not apply to --case-study"),
    (lambda tmp: SHIPPED, ["--trials", "02", "--tune", "all-trials"],
     "tune = 'all-trials': needs at least 2 trials"),
    (lambda tmp: SHIPPED, ["--grid"], "--grid is the case study's grid search"),
])
def test_bad_broad_input_gets_one_line_exit_2_and_nothing_written(tmp_path, capsys, make,
                                                                  argv, message):
    folder = make(tmp_path)
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(folder), "--estimators", "madgwick",
                 "--out", str(out), "--quiet", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())


# --- tuning: never scored on the trials it was tuned on ---------------------------

def test_the_folds_are_disjoint_and_every_trial_is_scored_once():
    from benchmarks.broad.tuning import training_sets
    trials = [f"{n:02d}_trial" for n in range(1, 8)]
    sets = training_sets(trials, "all-trials")
    assert sorted(t for _, scored in sets for t in scored) == sorted(trials)
    for training, scored in sets:
        assert training and not set(training) & set(scored)
    assert training_sets(trials, "per-trial")[3] == ([trials[3]], [trials[3]])
    from dynamics.validation import InvalidParameterError
    with pytest.raises(InvalidParameterError, match="needs at least 2 trials"):
        training_sets(trials[:1], "all-trials")


@pytest.fixture(scope="module")
def trial_02_case():
    from benchmarks.broad.tuning import TrialCase
    name = "02_undisturbed_slow_rotation_B"
    return TrialCase(name, imu_inputs(open_broad(SHIPPED).load(name)))


def test_madgwick_is_tuned_on_the_authors_grid_to_its_minimum(trial_02_case):
    from benchmarks.broad.tuning import TrialsScore, tune_on
    found = tune_on("madgwick-broad", [trial_02_case])
    score = TrialsScore("madgwick-broad", [trial_02_case])
    # The minimum of the grid: no grid point the search saw is better, the
    # authors' chosen β (0.12, published 1.49682° on this trial) included.
    at_chosen = score(lambda _scenario: {"beta": 0.12})
    assert abs(at_chosen - 1.49682) < 2e-4
    assert found["loss"] <= at_chosen
    neighbours = [b for b in case_study.MADGWICK_BETAS
                  if abs(b - found["values"]["beta"]) < 0.0150]
    assert all(found["loss"] <= score(lambda _s, b=b: {"beta": b}) for b in neighbours)


@pytest.mark.slow      # a tuning of the MEKF on a whole trial: 4 s
def test_the_mekf_tuner_lowers_its_training_loss(trial_02_case, monkeypatch):
    from benchmarks.broad import tuning
    monkeypatch.setattr(tuning, "MAX_EVALUATIONS", 14)
    found = tuning.tune_on("mekf", [trial_02_case])
    assert set(found["values"]) == {"gyro_noise", "gyro_bias_random_walk", "gravity_density",
                                    "heading_density"}
    # It searched, and found settings strictly better on its training trial
    # than the defaults (the search starts from them and keeps the best: a
    # search that never moved would return the defaults' loss itself).
    assert 1 < found["evaluations"] <= 14 + 1
    assert found["loss"] < found["loss_default"] - 1e-3


@pytest.mark.slow      # two tunings, each scored on the other trial: 4 s
def test_tuning_all_trials_scores_each_trial_with_the_other_trials_settings(tmp_path, capsys):
    import pandas as pd
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(SHIPPED), "--estimators", "madgwick,vqf,dead-reckoning",
                 "--tune", "all-trials", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "cross-validation" in printed
    tuned = pd.read_csv(out / "broad_tuning.csv", dtype={"training": str, "scored": str})
    # Only Madgwick tunes (VQF keeps its defaults; dead reckoning has nothing to tune).
    assert list(tuned["estimator"]) == ["madgwick", "madgwick"]
    assert set(tuned["training"]) == {"02", "07"} and set(tuned["scored"]) == {"02", "07"}
    assert (tuned["training"] != tuned["scored"]).all()
    trials = pd.read_csv(out / "broad_trials.csv")
    default = main(["broad", "--broad", str(SHIPPED), "--estimators", "madgwick",
                    "--out", str(tmp_path / "default"), "--quiet"])
    assert default == 0
    untuned = pd.read_csv(tmp_path / "default" / "broad_trials.csv")
    assert (untuned["scored_against"] == "reference").all()
    # Trial 07 is scored with the β tuned on 02, not with the default β.
    assert trials.loc[trials.estimator == "madgwick", "total_rmse_deg"].iloc[1] != \
        untuned.loc[untuned.estimator == "madgwick", "total_rmse_deg"].iloc[1]


def test_the_authors_grid_gives_their_best_beta_on_trial_02():
    # Their case_study/results_madgwick_average_rmse.json, trial 02's
    # minimum_value over the β grid: total 1.4835498°, heading 1.1998357°,
    # inclination 0.7698124° (their filter in single precision: within 1e-4°).
    grid = case_study.trial_grid(open_broad(SHIPPED), "02_undisturbed_slow_rotation_B",
                                 "madgwick-broad")
    assert grid.shape == (len(case_study.MADGWICK_BETAS), 3)
    np.testing.assert_allclose(grid.min(axis=0), [1.4835498, 1.1998357, 0.7698124], atol=1e-4)


@pytest.mark.slow      # the Kalman filters tuned on each half trial: 4 s
def test_tuning_halves_reads_no_reference_and_is_judged_on_the_second_half(tmp_path,
                                                                          monkeypatch):
    import pandas as pd
    from dataclasses import replace
    from benchmarks.broad import tuning
    from benchmarks.broad.tuning import LikelihoodScore, TrialCase, first_half_of
    monkeypatch.setattr(tuning, "MAX_EVALUATIONS", 8)
    name = "02_undisturbed_slow_rotation_B"
    recording = open_broad(SHIPPED).load(name)
    # The loss reads no reference: the same number with the reference erased.
    half = first_half_of(recording)
    blind = replace(half, reference_quat=np.full_like(half.reference_quat, np.nan))
    settings_of = (lambda _scenario: {"gyro_noise": 3e-6})
    assert LikelihoodScore("mekf", [TrialCase(name, imu_inputs(half))])(settings_of) == \
        LikelihoodScore("mekf", [TrialCase(name, imu_inputs(blind))])(settings_of)
    # Settings that refuse more readings than the defaults are out of
    # bounds: the likelihood per reading compares settings over the same
    # readings (a tight gate refuses what fits worst, and would score better).
    score = LikelihoodScore("mekf", [TrialCase(name, imu_inputs(half))])
    tight = (lambda _scenario: {"gate_probability": 0.2})
    total, updates, refused = score.sums(tight)
    assert refused > score.sums(lambda _scenario: {})[2] + 0.01 * score.readings
    assert math.isfinite(total / updates) and score(tight) == math.inf
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(SHIPPED), "--trials", "02", "--estimators",
                 "mekf,madgwick", "--tune", "halves", "--out", str(out), "--quiet"]) == 0
    tuned = pd.read_csv(out / "broad_tuning.csv", dtype={"training": str, "scored": str})
    # Only the Kalman filter tunes without a reference (Madgwick has no innovations).
    assert list(tuned["estimator"]) == ["mekf"]
    row = tuned.iloc[0]
    assert 1 < row["evaluations"] <= 8 + 1
    assert row["training_loss"] < row["training_loss_default"]
    assert row["held_out_verdict"] in ("better", "not better: keep the defaults")
    assert (row["held_out_verdict"] == "better") == (row["held_out_loss"]
                                                      < row["held_out_loss_default"])
    assert 0.0 <= row["held_out_refused_share"] <= row["held_out_refused_share_default"] + 0.01
    # Every estimator is scored on the second half only, the tuned MEKF as the table says.
    trials = pd.read_csv(out / "broad_trials.csv")
    second = recording.movement.copy()
    second[:recording.n_samples // 2] = False
    assert (trials["movement_samples"] == np.count_nonzero(second)).all()
    mekf = trials[trials["estimator"] == "mekf"].iloc[0]
    assert mekf["total_rmse_deg"] == pytest.approx(row["held_out_rmse_deg"], rel=1e-9)


def test_a_folder_given_as_dot_is_named_in_the_attribution(tmp_path, monkeypatch):
    """A user's recordings in the current folder (``--broad phone.toml``): the
    credit names that folder, not an empty name ("the recordings in ;")."""
    from benchmarks.broad.dataset import dataset_attribution
    monkeypatch.chdir(tmp_path)
    said = dataset_attribution(Path("."))
    assert f"the recordings in {tmp_path.name};" in said
    (tmp_path / "README.md").write_text("# Phone walks, 2026\n")
    assert f"the recordings in {tmp_path.name} (README.md: Phone walks, 2026)" in \
        dataset_attribution(Path("."))


@pytest.mark.slow      # 5 s
def test_the_trials_table_puts_a_filters_claimed_errors_beside_its_rmse(tmp_path):
    """broad_trials.csv: heading_sd_deg and inclination_sd_deg for a filter
    that keeps a covariance (the MEKF, its smoother), NaN for one that keeps
    none (Madgwick's), right after the three RMSEs."""
    import pandas as pd
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(SHIPPED), "--trials", "02",
                 "--estimators", "mekf,mekf-smoother,madgwick", "--out", str(out),
                 "--quiet"]) == 0
    trials = pd.read_csv(out / "broad_trials.csv")
    columns = list(trials.columns)
    assert columns.index("heading_sd_deg") == columns.index("inclination_rmse_deg") + 1
    assert columns.index("inclination_sd_deg") == columns.index("heading_sd_deg") + 1
    trials = trials.set_index("estimator")
    for name in ("mekf", "mekf-smoother"):
        for column in ("heading_sd_deg", "inclination_sd_deg"):
            assert 0.0 < trials.loc[name, column] < 5.0
    # The smoother knows more than each of its passes: it claims less.
    assert trials.loc["mekf-smoother", "heading_sd_deg"] < trials.loc["mekf", "heading_sd_deg"]
    assert trials.loc[["madgwick"], ["heading_sd_deg", "inclination_sd_deg"]].isna().all(axis=None)


def _claimed_against_drawn(covariance, rng, n=20000):
    """Attitudes q = q̂ ⊗ δq(δθ), δθ ~ N(0, C) (the filters' body-frame
    error), scored by the authors' metric against q̂: the sums of squared
    heading and tilt errors over the n draws, and what ``claimed_deg`` says
    of q̂ with C."""
    from scipy.spatial.transform import Rotation
    from benchmarks.broad.metric import claimed_deg
    estimate = Rotation.random(random_state=rng)
    draws = rng.multivariate_normal(np.zeros(3), covariance, size=n)
    truth = (estimate * Rotation.from_rotvec(draws)).as_quat(scalar_first=True)
    q_hat = np.tile(estimate.as_quat(scalar_first=True), (n, 1))
    errors = errors_deg(q_hat, truth)
    claimed = claimed_deg(q_hat, np.tile(covariance, (n, 1, 1)), truth, np.ones(n, bool))
    up = estimate.inv().apply([0.0, 0.0, 1.0])
    return errors, claimed, up


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_claimed_heading_and_tilt_are_what_the_covariance_gives(seed):
    """claimed_deg against draws from the covariance it reads: the heading
    error's squares sum, over n draws, to n σ_h² within 5 standard
    deviations of a χ²(n) (√(2n) σ_h²); the tilt's, a weighted sum of two
    χ²(1), to its mean n tr(C_t) within 5 of its standard deviation
    √(2n tr(C_t²)). A covariance a quarter of the one drawn from (σ halved)
    is shown to fail the same bound."""
    rng = np.random.default_rng(seed)
    root = rng.normal(size=(3, 3)) * math.radians(1.0)
    covariance = root @ root.T + np.eye(3) * math.radians(0.1) ** 2
    errors, claimed, up = _claimed_against_drawn(covariance, rng)
    n = len(errors["heading"])
    heading_var = math.radians(claimed["heading_sd_deg"]) ** 2
    heading_sum = np.sum(np.radians(errors["heading"]) ** 2)
    assert abs(heading_sum - n * heading_var) < 5 * math.sqrt(2 * n) * heading_var
    projector = np.eye(3) - np.outer(up, up)
    tilt = projector @ covariance @ projector
    assert math.radians(claimed["inclination_sd_deg"]) ** 2 == pytest.approx(np.trace(tilt))
    tilt_sum = np.sum(np.radians(errors["inclination"]) ** 2)
    assert abs(tilt_sum - n * np.trace(tilt)) < 5 * math.sqrt(2 * n * np.trace(tilt @ tilt))
    # Mistuned: the filter claims a quarter of its covariance.
    assert abs(heading_sum - n * heading_var / 4) > 5 * math.sqrt(2 * n) * heading_var / 4


def test_claimed_is_nan_without_a_covariance_or_a_scored_sample():
    from benchmarks.broad.metric import CLAIMED, claimed_deg
    q = np.tile([1.0, 0.0, 0.0, 0.0], (5, 1))
    assert all(math.isnan(v) for v in claimed_deg(q, None, q, np.ones(5, bool)).values())
    found = claimed_deg(q, np.tile(np.eye(3), (5, 1, 1)), q, np.zeros(5, bool))
    assert set(found) == set(CLAIMED) and all(math.isnan(v) for v in found.values())


def test_a_held_out_verdict_is_not_better_where_the_tuning_refuses_more_readings():
    # 0.32° → 60° on a log whose tuned filter refused 44 % of its field
    # readings, with a better likelihood per reading used: "better" before.
    from benchmarks.broad.tuning import held_out_verdict
    found = {"held_out_loss": -16.65, "held_out_loss_default": -14.48,
             "held_out_refused_share": 0.44, "held_out_refused_share_default": 0.0}
    assert held_out_verdict(found) == ("not better: refuses 44% of the readings where the "
                                       "defaults refuse 0%; keep the defaults")
    assert held_out_verdict({**found, "held_out_refused_share": 0.005}) == "better"
    assert held_out_verdict({**found, "held_out_loss": -14.0, "held_out_refused_share": 0.0}) == \
        "not better: keep the defaults"


def test_the_noise_note_says_the_sigmas_given(tmp_path, capsys):
    # The note of what the inputs assume says the σ the filters took: the
    # one given on the command line, not its default.
    assert main(["broad", "--trials", "07", "--estimators", "mekf", "--accelerometer-sigma",
                 "0.5", "--out", str(tmp_path / "out"), "--quiet"]) == 0
    note = next(line for line in capsys.readouterr().err.splitlines()
                if "nothing is taken from a rest" in line)
    assert ("the noise is the defaults but the accelerometer's as given (gyro 0.001 rad/√s, "
            "accelerometer 0.5 m/s², magnetometer 4 µT)") in note
