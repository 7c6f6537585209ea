"""``broad`` on hostile folders, and the honesty of its tables (issue 28).

Every folder here is made from the shipped trials (``datasets/broad/``),
cut to a few thousand samples around the start of their movement so that
a run takes a moment, and then damaged one way. Bad input must be one line
naming the parameter, the value and the rule, exit 2 and nothing written;
a table must never average fewer trials than it names.
"""
import json
import math
import re

import numpy as np
import pandas as pd
import pytest

from benchmarks.broad import benchmark, figures, inputs
from benchmarks.broad.dataset import open_broad
from benchmarks.broad.metric import METRICS
from benchmarks.cli import main
from benchmarks.shipped import shipped_file
from dynamics.validation import InvalidParameterError

SHIPPED = shipped_file("datasets/broad/trials.json").parent
TRIAL_02 = "02_undisturbed_slow_rotation_B"
TRIAL_07 = "07_undisturbed_fast_rotation_B"
#: The samples kept of each shipped trial: 1,449 of rest (02) and 1,573 (07)
#: before the movement, every movement sample with a reference.
CUTS = {TRIAL_02: slice(10000, 16000), TRIAL_07: slice(6000, 12000)}
#: The published keys of a .mat trial, by the toolkit's.
MAT_KEYS = {"imu_gyr_radps": "imu_gyr", "imu_acc_mps2": "imu_acc", "imu_mag_uT": "imu_mag",
            "opt_quat": "opt_quat", "movement": "movement", "sampling_rate_hz": "sampling_rate"}
PER_SAMPLE = ("imu_gyr_radps", "imu_acc_mps2", "imu_mag_uT", "opt_quat", "movement")


def _arrays(name: str) -> dict:
    """A shipped trial's arrays, cut to :data:`CUTS`."""
    with np.load(SHIPPED / f"{name}.npz") as archive:
        arrays = {key: archive[key] for key in archive.files}
    for key in PER_SAMPLE:
        arrays[key] = arrays[key][CUTS[name]]
    return arrays


def _folder(tmp_path, change=None, index=None, layout="npz", names=(TRIAL_02, TRIAL_07)):
    """A BROAD folder of the cut trials ``names``; ``change(name, arrays)``
    damages a trial's arrays, ``index(described)`` the trials.json."""
    folder = tmp_path / "broad"
    folder.mkdir()
    described = json.loads((SHIPPED / "trials.json").read_text())
    if index:
        index(described)
    (folder / "trials.json").write_text(json.dumps(described))
    for name in names:
        arrays = _arrays(name)
        if change:
            change(name, arrays)
        if layout == "mat":
            from scipy.io import savemat
            (folder / "data_mat").mkdir(exist_ok=True)
            savemat(folder / "data_mat" / f"{name}.mat",
                    {MAT_KEYS[key]: value for key, value in arrays.items() if key in MAT_KEYS})
        else:
            np.savez(folder / f"{name}.npz", **arrays)
    return folder


def _on(trial, change):
    """``change(arrays)`` applied to ``trial`` only."""
    return lambda name, arrays: change(arrays) if name == trial else None


def _run(tmp_path, capsys, folder, *argv, estimators="madgwick,mekf"):
    """``broad`` on ``folder`` (``estimators`` None: its default list): its
    exit status, stdout, stderr and output folder."""
    out = tmp_path / "out"
    named = ["--estimators", estimators] if estimators is not None else []
    status = main(["broad", "--broad", str(folder), *named, "--out", str(out), "--quiet", *argv])
    captured = capsys.readouterr()
    return status, captured.out, captured.err, out


def _refused(tmp_path, capsys, folder, message, *argv, **kw):
    status, _, err, out = _run(tmp_path, capsys, folder, *argv, **kw)
    assert status == 2, err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())
    return err


# --- unreadable and malformed trials ------------------------------------------------

@pytest.mark.parametrize("content, message", [
    (b"", "is empty; a BROAD trial is a MATLAB file"),
    (b"not a MATLAB file, just text\n" * 20, "cannot be read as a MATLAB file"),
    (b"MATLAB 5.0 MAT-file" + bytes(200), "cannot be read as a MATLAB file")])
def test_a_mat_trial_that_is_empty_or_text_is_one_line(tmp_path, capsys, content, message):
    folder = _folder(tmp_path, layout="mat")
    (folder / "data_mat" / f"{TRIAL_02}.mat").write_bytes(content)
    _refused(tmp_path, capsys, folder, f"{TRIAL_02}.mat': {message}")


def test_a_sampling_rate_of_several_values_is_one_line(tmp_path, capsys):
    folder = _folder(tmp_path, _on(TRIAL_02, lambda a: a.update(
        sampling_rate_hz=np.array([[285.7, 100.0]]))), layout="mat")
    _refused(tmp_path, capsys, folder,
             "sampling_rate_hz = [[285.7, 100.0]] must be one positive number (Hz)")


def test_a_mat_trial_reads_as_its_npz(tmp_path):
    # The (N, 1) movement and the (1, 1) rate MATLAB stores are read as (N,) and a number.
    mat = open_broad(_folder(tmp_path, layout="mat", names=(TRIAL_02,))).load(TRIAL_02)
    arrays = _arrays(TRIAL_02)
    assert np.array_equal(mat.movement, arrays["movement"].astype(bool))
    assert mat.rate_hz == float(arrays["sampling_rate_hz"])
    assert np.array_equal(mat.accelerometer_mps2, arrays["imu_acc_mps2"])


@pytest.mark.parametrize("key, row, unit", [
    ("imu_acc_mps2", 0, "±20000 m/s²"), ("imu_mag_uT", 0, "±50000 µT"),
    ("imu_acc_mps2", 3000, "±20000 m/s²"), ("imu_mag_uT", 3000, "±50000 µT")])
def test_a_huge_reading_is_refused_before_anything_overflows(tmp_path, capsys, key, row, unit):
    def huge(arrays):
        arrays[key][row] = [1e300, -1e300, 1e300]
    folder = _folder(tmp_path, _on(TRIAL_02, huge))
    with np.errstate(all="raise"):                  # nothing may overflow on the way
        _refused(tmp_path, capsys, folder, f"{key} must be within {unit} (ten times any such "
                 f"sensor's range); row {row} is [1e+300, -1e+300, 1e+300]")


@pytest.mark.parametrize("key, factor, median", [
    ("imu_mag_uT", 1e3, "4.454e+04 µT"), ("imu_mag_uT", 1e-2, "0.4454 µT"),
    ("imu_acc_mps2", 1 / 9.80665, "1.002 m/s²")])
def test_a_channel_in_another_unit_is_refused_by_its_median_norm(tmp_path, capsys, key, factor,
                                                                  median):
    # A field in nT or gauss, an acceleration in g, under a key that names
    # µT or m/s²: the median norm (trial 02's: 44.5 µT, 9.8 m/s²) says so.
    def other_unit(arrays):
        arrays[key] = arrays[key] * factor
    folder = _folder(tmp_path, _on(TRIAL_02, other_unit))
    _refused(tmp_path, capsys, folder, f"{key}'s median norm is {median}")


@pytest.mark.parametrize("key", ["imu_acc_mps2", "imu_mag_uT"])
def test_a_channel_of_zeros_is_refused_as_no_reading(tmp_path, capsys, key):
    # Every row zero is no reading at all (it had loaded, and failed later
    # on the start attitude's rule, or run the filters on nothing).
    def zeros(arrays):
        arrays[key] = np.zeros_like(arrays[key])
    folder = _folder(tmp_path, _on(TRIAL_02, zeros))
    _refused(tmp_path, capsys, folder, f"{key} holds only zeros: no ")


def test_a_field_ten_times_stronger_than_earths_is_still_a_reading(tmp_path):
    # The bound refuses corrupt values, not a magnet near the sensor.
    def magnet(arrays):
        arrays["imu_mag_uT"][3000:3100] *= 30.0
    recording = open_broad(_folder(tmp_path, _on(TRIAL_02, magnet))).load(TRIAL_02)
    assert np.abs(recording.magnetometer_uT).max() > 1000.0


def test_a_two_sample_trial_is_refused_with_the_rule(tmp_path, capsys):
    def two_samples(arrays):
        moving = int(np.argmax(arrays["movement"]))
        for key in PER_SAMPLE:
            arrays[key] = arrays[key][moving - 1:moving + 1]   # one at rest, one moving
    folder = _folder(tmp_path, _on(TRIAL_02, two_samples))
    _refused(tmp_path, capsys, folder, f"has 2 samples; a trial needs at least "
             f"{inputs.MIN_SAMPLES} to be run and scored")


# --- unusable first samples ----------------------------------------------------------

@pytest.mark.parametrize("damage", ["zero accelerometer", "zero magnetometer", "parallel"])
def test_an_unusable_first_sample_starts_the_trial_at_the_first_usable_one(tmp_path, damage):
    def first(arrays):
        if damage == "parallel":
            arrays["imu_mag_uT"][0] = 4.0 * arrays["imu_acc_mps2"][0]
        else:
            arrays["imu_acc_mps2" if "accelerometer" in damage else "imu_mag_uT"][0] = 0.0
    # The trial starts at its first usable sample: the one before is left
    # out, and said (a start taken there but used at sample 0 would be off by
    # the body's turn between the two).
    with pytest.warns(UserWarning, match="its first sample .* comes before the first sample "
                      "where both sensors have read .* left out"):
        recording = open_broad(_folder(tmp_path, _on(TRIAL_02, first))).load(TRIAL_02)
    whole = _arrays(TRIAL_02)
    assert recording.n_samples == len(whole["imu_gyr_radps"]) - 1
    np.testing.assert_array_equal(recording.accelerometer_mps2, whole["imu_acc_mps2"][1:])
    prepared = inputs.imu_inputs(recording)
    at_one = inputs.initial_attitude(whole["imu_acc_mps2"][1], whole["imu_mag_uT"][1],
                                     prepared.references)
    np.testing.assert_allclose(prepared.scenario.initial_state, at_one, atol=1e-15)
    for readings in prepared.sensors.vectors:
        assert readings.available.all()


def test_a_dropout_at_the_start_changes_the_scores_by_next_to_nothing(tmp_path, capsys):
    def zero(arrays):
        arrays["imu_acc_mps2"][0] = 0.0
        arrays["imu_mag_uT"][:5] = 0.0
    status, _, err, out = _run(tmp_path, capsys, _folder(tmp_path, _on(TRIAL_02, zero),
                                                         names=(TRIAL_02,)))
    assert status == 0, err
    assert "note: trial 02_undisturbed_slow_rotation_B: 1 accelerometer reading and 5 " \
           "magnetometer readings exactly zero (dropouts), left out" in err
    assert "note: trial 02_undisturbed_slow_rotation_B: its first 5 samples" in err
    assert "Traceback" not in err
    damaged = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    (tmp_path / "intact").mkdir()
    intact = benchmark.run_trial(open_broad(_folder(tmp_path / "intact", names=(TRIAL_02,))),
                                 TRIAL_02, ["madgwick", "mekf"])[0]
    for row in intact:
        assert damaged.loc[row["estimator"], "total_rmse_deg"] == \
            pytest.approx(row["total_rmse_deg"], abs=0.01)


def test_a_sensor_that_stops_is_said_with_when_and_what_the_filters_do(tmp_path, capsys):
    # The magnetometer stops 4,000 samples in (its last 2,000, 7 s at 285.7
    # Hz, are zeros); the accelerometer is lost for 1.5 s in the middle.
    # Both are said, with when, how long and the filters' gyro-only stretch;
    # the trial is still scored.
    def stop(arrays):
        arrays["imu_mag_uT"][4000:] = 0.0
        arrays["imu_acc_mps2"][2000:2429] = 0.0
    status, _, err, out = _run(tmp_path, capsys, _folder(tmp_path, _on(TRIAL_02, stop),
                                                         names=(TRIAL_02,)))
    assert status == 0, err
    dt = 1.0 / 285.7
    assert (f"trial 02_undisturbed_slow_rotation_B: its magnetometer reads nothing from "
            f"{4000 * dt:.1f} s to the end ({2000 * dt:.3g} s): 33% of the trial, where the "
            "filters hold the heading with the gyro alone") in err
    assert (f"its accelerometer reads nothing from {2000 * dt:.1f} s to {2429 * dt:.1f} s "
            f"({429 * dt:.3g} s): 7% of the trial, where the filters hold the inclination "
            "with the gyro alone") in err
    assert len(pd.read_csv(out / "broad_trials.csv")) == 2


def test_silences_are_the_stretches_long_against_the_sensors_own_interval():
    from benchmarks.broad.trial_notes import silences
    dt = 0.01
    read = np.zeros(1000, dtype=bool)
    read[::20] = True            # every 0.2 s: a stretch of 19 samples is its own pace
    assert silences(read, dt) == []
    read[300:700] = False        # 4 s without a reading (>= 10 intervals of 0.2 s, >= 1 s)
    assert silences(read, dt) == [(281, 700)]
    read[900:] = False           # and from 8.81 s to the end: 1.19 s, under 10 intervals
    assert silences(read, dt) == [(281, 700)]
    every = np.ones(1000, dtype=bool)
    every[500:599] = False       # 0.99 s: under a second
    assert silences(every, dt) == []
    every[500:600] = False       # 1 s
    assert silences(every, dt) == [(500, 600)]
    every[0:150] = False         # the longest first
    assert silences(every, dt) == [(0, 150), (500, 600)]
    assert silences(np.zeros(50, dtype=bool), dt) == [(0, 50)]


def test_a_trial_with_no_usable_pair_is_refused_with_the_rule(tmp_path, capsys):
    # Every other reading of both a dropout, the others' field parallel to
    # gravity: the latest readings of the two are parallel at every sample.
    def no_pair(arrays):
        arrays["imu_acc_mps2"][0::2] = 0.0
        arrays["imu_mag_uT"][0::2] = 0.0
        arrays["imu_mag_uT"][1::2] = 3.0 * arrays["imu_acc_mps2"][1::2]
    folder = _folder(tmp_path, _on(TRIAL_02, no_pair))
    _refused(tmp_path, capsys, folder, "no accelerometer reading and magnetometer reading, the "
             "latest of each at a sample, are both non-zero and at least 1° apart, which the "
             "start attitude is taken from")


def test_a_rest_of_dropouts_is_no_rest_and_none_is_needed(tmp_path, capsys):
    # Nothing is taken from a rest: a trial whose rest is all dropouts starts
    # at its first usable sample, says so, and is scored.
    moving = int(np.argmax(_arrays(TRIAL_02)["movement"]))

    def dead(arrays):
        arrays["imu_acc_mps2"][:moving] = 0.0
    status, _, err, out = _run(tmp_path, capsys, _folder(tmp_path, _on(TRIAL_02, dead),
                                                         names=(TRIAL_02,)))
    assert status == 0, err
    assert f"its first {moving} samples" in err
    scores = pd.read_csv(out / "broad_trials.csv").set_index("estimator")["total_rmse_deg"]
    assert scores.notna().all()


# --- trials.json and the case study's files --------------------------------------------

def _groups_of(trial, value):
    def change(described):
        described["trials"][trial]["groups"] = value
    return change


@pytest.mark.parametrize("index, message", [
    (_groups_of(TRIAL_02, "all_trials"),
     f"trial {TRIAL_02}'s groups = 'all_trials': must be a list of group names"),
    (_groups_of(TRIAL_02, ["all_trials", 3]),
     f"trial {TRIAL_02}'s groups = ['all_trials', 3]: must be a list of group names"),
    (_groups_of(TRIAL_02, ["all_trials", "rotatoin"]),
     f"trial {TRIAL_02}'s group = 'rotatoin': must be one of the groups the index declares"),
    (_groups_of(TRIAL_02, ["all_trials", "all_trials"]), "must name each group once"),
    (lambda d: d.update(trials=list(d["trials"])), "trials = ['01_undisturbed"),
    (lambda d: d["groups"][0].update(level="0"), "group all_trials's level = '0': must be "
                                                 "a whole number"),
])
def test_a_malformed_trials_json_is_one_line(tmp_path, capsys, index, message):
    _refused(tmp_path, capsys, _folder(tmp_path, index=index), message)


def test_an_index_that_is_not_an_object_is_one_line(tmp_path, capsys):
    folder = _folder(tmp_path)
    (folder / "trials.json").write_text("[1, 2, 3]")
    _refused(tmp_path, capsys, folder, "trials.json is not BROAD's index")
    (folder / "trials.json").write_text('{"groups": [')
    _refused(tmp_path, capsys, folder, "trials.json cannot be read as JSON")


@pytest.mark.parametrize("content, message", [
    ("{not json", "cannot be read as JSON (JSONDecodeError"),
    ("[1, 2]", "holds list; must be an object with the authors' trials"),
    ('{"trials": [1]}', "trials is list; must be an object of trials by name"),
    (json.dumps({"trials": {TRIAL_02: [1.0]}}), f"trial {TRIAL_02} is list"),
    (json.dumps({"trials": {TRIAL_02: {"tagp_parameters": {"total_rmse_deg": "1.5"}}}}),
     f"trial {TRIAL_02}'s tagp_parameters total_rmse_deg = '1.5'; must be a number"),
])
def test_a_damaged_case_study_file_is_one_line(tmp_path, capsys, content, message):
    folder = _folder(tmp_path, names=(TRIAL_02,))
    (folder / "case_study").mkdir()
    (folder / "case_study" / "results_mahony_average_rmse.json").write_text(content)
    _refused(tmp_path, capsys, folder, f"results_mahony_average_rmse.json': {message}",
             "--case-study", estimators=None)


# --- the sigmas -------------------------------------------------------------------------

@pytest.mark.parametrize("flag, value, message", [
    ("--magnetometer-sigma", "1e300", "magnetometer_sigma = 1e+300: must be below 1.34e+154 "
                                      "so that its square (a variance) is finite"),
    ("--accelerometer-sigma", "inf", "accelerometer_sigma = inf: must be finite"),
    ("--accelerometer-sigma", "nan", "accelerometer_sigma = nan: must be finite"),
])
def test_a_sigma_whose_square_is_not_finite_is_one_line(tmp_path, capsys, flag, value, message):
    _refused(tmp_path, capsys, _folder(tmp_path, names=(TRIAL_02,)), message, flag, value)


def test_the_sigmas_are_checked_where_the_filters_take_them():
    recording = open_broad(SHIPPED).load(TRIAL_02)
    with pytest.raises(InvalidParameterError, match=r"^magnetometer_sigma = 1e\+200: must be "
                                                    "below"):
        inputs.references_and_variances(recording, {"magnetometer": 1e200})
    with pytest.raises(InvalidParameterError, match=r"^accelerometer_sigma = 0.0: must be > 0"):
        inputs.imu_inputs(recording, sigmas={"accelerometer": 0.0})
    with pytest.raises(InvalidParameterError, match="sigmas = 'gyro': must name one of"):
        inputs.checked_sigmas({"gyro": 1.0})
    _, variances = inputs.references_and_variances(recording, {"accelerometer": 1e100})
    assert variances["accelerometer"] == 1e200


# --- the trials selected -------------------------------------------------------------------

def test_a_trial_named_twice_is_refused_naming_it():
    dataset = open_broad(SHIPPED)
    for names in (["02", "2"], ["02", "07", TRIAL_02], [" 2", "002"]):
        with pytest.raises(InvalidParameterError, match=f"names trial {TRIAL_02} a second "
                                                        "time"):
            dataset.selected(names)
    assert dataset.selected(["07", "2"]) == [TRIAL_07, TRIAL_02]
    assert dataset.selected(None) == dataset.available == dataset.selected([])


@pytest.mark.parametrize("tune", ["none", "per-trial"])
def test_the_command_refuses_a_trial_named_twice(tmp_path, capsys, tune):
    err = _refused(tmp_path, capsys, _folder(tmp_path), f"names trial {TRIAL_02} a second time",
                   "--trials", "02,07,2", "--tune", tune, estimators="madgwick")
    assert "each trial may be named once" in err
    with pytest.raises(InvalidParameterError, match="a second time"):
        benchmark.run_broad(open_broad(SHIPPED), [TRIAL_02, TRIAL_02], ["madgwick"], quiet=True)


# --- tables that cannot score everything ---------------------------------------------------

def _no_reference_in_movement(arrays):
    arrays["opt_quat"][arrays["movement"].astype(bool)] = np.nan


def _never_moves(arrays):
    arrays["movement"][:] = 0


def test_a_trial_with_nothing_to_score_is_left_out_by_name(tmp_path, capsys):
    folder = _folder(tmp_path, _on(TRIAL_02, _no_reference_in_movement))
    status, printed, err, out = _run(tmp_path, capsys, folder)
    assert status == 0, err
    assert "all_trials (1 of 2 scored)" in printed and "slow (0 of 1 scored)" in printed
    assert "fast (1)" in printed and "Empty DataFrame" not in printed
    assert f"left out of the means: {TRIAL_02} has no reference during its movement (all " \
           "4551 samples)" in printed
    groups = pd.read_csv(out / "broad_groups.csv", keep_default_na=False,
                         na_values=["NaN", "nan", ""])
    trials = pd.read_csv(out / "broad_trials.csv")
    on_07 = trials[trials.trial == TRIAL_07].set_index("estimator")
    for row in groups[groups.group == "all_trials"].itertuples():
        assert (row.trials, row.scored_trials) == (2, 1)
        assert row.left_out.startswith("02 has no reference during its movement")
        assert row.total_rmse_deg == pytest.approx(on_07.loc[row.estimator, "total_rmse_deg"])
    slow = groups[groups.group == "slow"]
    assert slow[list(METRICS)].isna().all().all() and (slow.scored_trials == 0).all()
    assert (trials[trials.trial == TRIAL_02].scored_samples == 0).all()


@pytest.mark.parametrize("damage, why", [
    (_no_reference_in_movement, "has no reference during its movement"),
    (_never_moves, "never moves (no sample of its movement flag is set)")])
def test_a_selection_with_nothing_to_score_is_refused(tmp_path, capsys, damage, why):
    folder = _folder(tmp_path, _on(TRIAL_02, damage), names=(TRIAL_02,))
    _refused(tmp_path, capsys, folder, f"trials = '02': nothing to score: {TRIAL_02} {why}")
    with pytest.raises(InvalidParameterError, match=re.escape(f"nothing to score: {TRIAL_02} "
                                                              f"{why}")):
        open_broad(folder).selected(None)          # before anything runs


def test_a_group_mean_is_nan_where_an_estimator_has_no_score_on_one_of_its_trials():
    # Exact: A diverged on 07, B did not; trial 02's scores are the group's.
    dataset = open_broad(SHIPPED)
    rows = []
    for trial, a, b in ((TRIAL_02, 1.0, 2.0), (TRIAL_07, math.nan, 4.0)):
        for name, value in (("a", a), ("b", b)):
            rows.append({"trial": trial, "estimator": name, "movement_samples": 10,
                         "scored_samples": 10, **{metric: value for metric in METRICS}})
    groups = benchmark.group_means(dataset, pd.DataFrame(rows)).set_index(
        ["group", "estimator"])
    assert math.isnan(groups.loc[("all_trials", "a"), "total_rmse_deg"])
    assert groups.loc[("all_trials", "a"), "nan_on"] == "07"
    assert groups.loc[("all_trials", "b"), "total_rmse_deg"] == 3.0
    assert groups.loc[("slow", "a"), "total_rmse_deg"] == 1.0       # 07 is not slow
    result = benchmark.BroadResult(trials=pd.DataFrame(rows), groups=groups.reset_index(),
                                   labels={"a": "A", "b": "B"}, curves={}, curve_trial="")
    text = benchmark.format_groups(result)
    assert "NaN: a has no score on trial 07 (it diverged there)" in text
    assert "all_trials (2)" in text


def test_the_group_table_says_on_which_trials_the_field_was_timed():
    # An offline estimator times its field where the delay's fit is clear:
    # the note says where, when that is not every trial
    rows = [{"trial": trial, "estimator": "vqf-offline", "mode": "offline",
             "movement_samples": 10, "scored_samples": 10, "magnetometer_delay_ms": delay,
             **{metric: 1.0 for metric in METRICS}}
            for trial, delay in ((TRIAL_02, 12.4), (TRIAL_07, math.nan))]
    dataset = open_broad(SHIPPED)
    for trials in (rows, rows[:1]):
        frame = pd.DataFrame(trials)
        result = benchmark.BroadResult(
            trials=frame, groups=benchmark.group_means(dataset, frame), curves={},
            labels={"vqf-offline": "VQF offline"}, curve_trial="")
        text = benchmark.format_groups(result)
        assert "vqf-offline: the magnetometer taken at its samples' times" in text
        assert ("where it was clear (1 of 2 trials)" in text) == (len(trials) == 2)


# --- what the tables say --------------------------------------------------------------------

@pytest.mark.slow      # the per-run EKF over a whole trial: 5 s
def test_the_trial_table_shows_the_share_of_readings_each_filter_rejected(tmp_path, capsys):
    def dropouts(arrays):
        arrays["imu_acc_mps2"][2000:2010] = 0.0        # ten readings that are none
    folder = _folder(tmp_path, _on(TRIAL_07, dropouts), names=(TRIAL_07,))
    status, printed, err, out = _run(tmp_path, capsys, folder,
                                     estimators="madgwick,ekf,mekf")
    assert status == 0, err
    trials = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    gated = trials.loc["ekf"]        # the workshop's EKF reads acc/mag as gated vectors
    share = gated["rejected_accelerometer"] / (gated["samples"] - 10)
    assert gated["rejected_accelerometer_share"] == pytest.approx(share)
    assert 0.2 < share < 0.9          # trial 07's movement: the vector filter's gate is busy
    # The MEKF's low-passed gravity (estimators.imu.gravity) takes every reading.
    assert trials.loc["mekf", "rejected_accelerometer_share"] == 0.0
    assert math.isnan(trials.loc["madgwick", "rejected_accelerometer_share"])
    header, *lines = printed.splitlines()
    assert header.rstrip().endswith("rejected acc/mag %")
    row = next(line for line in lines if " ekf " in line)
    assert row.split()[-1] == (f"{100 * share:.1f}/"
                               f"{100 * gated['rejected_magnetometer_share']:.1f}")
    assert next(line for line in lines if " madgwick " in line).split()[-1] == "-/-"


def test_the_figures_are_readable(tmp_path):
    folder = _folder(tmp_path, _on(TRIAL_02, _no_reference_in_movement))
    dataset = open_broad(folder)
    result = benchmark.run_broad(dataset, dataset.selected(), ["dead-reckoning", "madgwick"],
                                 quiet=True)
    # The first trial has nothing to score: the trial figure shows the next.
    assert result.curve_trial == TRIAL_07
    figure = figures.trial_figure(result)
    (axis,) = figure.axes
    assert axis.get_yscale() == "log" and axis.get_legend() is None and figure.legends
    shaded = [p for p in axis.patches if p.get_label().startswith("movement")]
    assert len(shaded) == 1                           # one movement phase
    start = np.argmax(result.curve_movement) / dataset.load(TRIAL_07).rate_hz
    assert shaded[0].get_x() == pytest.approx(start)
    figure = figures.groups_figure(result)
    assert all(ax.get_yscale() == "log" for ax in figure.axes) and figure.legends
    assert all(ax.get_legend() is None for ax in figure.axes)
    names = [t.get_text() for t in figure.axes[-1].get_xticklabels()]
    assert "all_trials\n(1 of 2 scored)" in names and "fast\n(1)" in names
    assert "NaN" in [t.get_text() for t in figure.axes[0].texts]   # slow: nothing scored


def test_an_intact_trial_takes_nothing_from_a_rest():
    # Gravity is the standard one, the vector filters' field the medians of
    # the first second, the noise the declared defaults: none depends on
    # where the movement starts.
    recording = open_broad(SHIPPED).load(TRIAL_02)
    references, variances = inputs.references_and_variances(recording)
    assert np.array_equal(references["accelerometer"], [0.0, 0.0, 9.80665])
    window = round(inputs.FIELD_WINDOW_S * recording.rate_hz)
    first = recording.magnetometer_uT[:window]
    assert np.linalg.norm(references["magnetometer"]) == pytest.approx(
        np.median(np.linalg.norm(first, axis=1)), rel=1e-12)
    assert references["magnetometer"][0] == 0.0 and references["magnetometer"][1] > 0.0
    assert variances == {name: sigma ** 2 for name, sigma in inputs.MOTION_SIGMAS.items()}
    assert inputs.start_sample(recording) == 0
    said = "\n".join(inputs.imu_inputs(recording).assumptions)
    assert "gravity: the standard 9.80665 m/s²" in said and "TRIAD on sample 0" in said


# --- a dataset of one's own in BROAD's layout ----------------------------------------

def test_trial_labels_keep_a_users_names_whole():
    from benchmarks.broad.dataset import trial_label
    assert trial_label(TRIAL_02) == "02"
    assert trial_label("my_phone_log") == "my_phone_log"
    assert trial_label("07_undisturbed_fast_rotation_B") == "07"
    # A user's name that looks like BROAD's is kept whole too: two of them
    # could share a number.
    assert trial_label("01_walk") == "01_walk" and trial_label("2024_walk") == "2024_walk"
    assert trial_label("walk") == "walk" and trial_label("12") == "12"


def _own_folder(tmp_path, readme: str | None):
    """The cut trial 02 as a user's trial ``my_phone_log``, with ``readme``
    (None: no README) and no LICENSE."""
    def rename(described):
        described["trials"] = {"my_phone_log": described["trials"][TRIAL_02]}
    folder = _folder(tmp_path, index=rename, names=(TRIAL_02,))
    (folder / f"{TRIAL_02}.npz").rename(folder / "my_phone_log.npz")
    if readme is not None:
        (folder / "README.md").write_text(readme)
    return folder


def test_a_users_dataset_is_credited_from_its_own_readme_and_named_whole(tmp_path, capsys):
    folder = _own_folder(tmp_path, "# Phone logs of the Kestrel lab\n\nCC0, recorded 2026.\n")
    status, printed, _, out = _run(tmp_path, capsys, folder, estimators="madgwick")
    assert status == 0
    credit = (out / "ATTRIBUTION.txt").read_text()
    assert "Phone logs of the Kestrel lab" in credit and "BROAD" not in credit
    assert "Laidig" not in printed and "Phone logs of the Kestrel lab" in printed
    trials = pd.read_csv(out / "broad_trials.csv")
    assert set(trials["trial"]) == {"my_phone_log"}
    assert "my_phone_log" in printed and " my " not in printed


def test_a_users_readme_that_cites_broad_does_not_make_it_broads(tmp_path):
    from benchmarks.broad.dataset import open_broad
    folder = _own_folder(tmp_path, "# Walks with my phone\n\nCompared with BROAD "
                                   "(doi:10.3390/data6070072).\n")
    credit = open_broad(folder).attribution
    assert "Walks with my phone" in credit and "Laidig" not in credit
    # Its figures are titled by its folder's name, not BROAD's.
    assert open_broad(folder).title == folder.name


def test_a_dataset_without_a_readme_is_credited_to_no_one_else(tmp_path, capsys):
    folder = _own_folder(tmp_path, None)
    status, _, _, out = _run(tmp_path, capsys, folder, estimators="madgwick")
    assert status == 0
    credit = (out / "ATTRIBUTION.txt").read_text()
    assert "no README or LICENSE" in credit and "BROAD" not in credit


def test_broad_itself_is_credited_as_its_authors_ask():
    from benchmarks.broad.dataset import ATTRIBUTION, open_broad
    assert open_broad(SHIPPED).attribution == ATTRIBUTION      # its README names BROAD's DOI
    assert open_broad(SHIPPED).title == "BROAD"
    assert "CC BY 4.0" in ATTRIBUTION and "Laidig" in ATTRIBUTION


# --- tuned on one dataset, scored on another -------------------------------------------

def _two_datasets(tmp_path):
    """The cut trial 07 as a training dataset, the cut trial 02 as the scored one."""
    train = _folder(tmp_path / "train", names=(TRIAL_07,))
    test = _folder(tmp_path / "test", names=(TRIAL_02,))
    return train, test


def test_settings_tuned_on_another_dataset_are_scored_on_this_one(tmp_path, capsys):
    (tmp_path / "train").mkdir()
    (tmp_path / "test").mkdir()
    train, test = _two_datasets(tmp_path)
    status, printed, _, out = _run(tmp_path, capsys, test, "--train", str(train),
                                   estimators="madgwick,dead-reckoning")
    assert status == 0
    assert "tuned on every trial of another dataset" in printed
    tunings = pd.read_csv(out / "broad_tuning.csv", dtype={"training": str, "scored": str})
    # Madgwick tuned on the training dataset's trial 07 alone, scored on 02;
    # dead reckoning has nothing to tune.
    assert list(tunings["estimator"]) == ["madgwick"]
    row = tunings.iloc[0]
    assert row["training"] == "07" and row["scored"] == "02"
    assert row["training_dataset"] == str(train)
    assert row["training_loss_deg"] <= row["training_loss_default_deg"]
    trials = pd.read_csv(out / "broad_trials.csv")
    assert set(trials["trial"]) == {TRIAL_02}


@pytest.mark.parametrize("same", ["folder", "copy", "mat"])
def test_a_training_dataset_holding_a_scored_recording_is_refused(tmp_path, capsys, same):
    # The same folder, a copy of it, or the same recording in the other
    # file format (.mat beside .npz).
    for sub in ("test", "mat"):
        (tmp_path / sub).mkdir()
    test = _folder(tmp_path / "test", names=(TRIAL_02,))
    if same == "folder":
        train, message = test, "is the dataset scored (--broad)"
    else:
        import shutil
        train = (shutil.copytree(test, tmp_path / "copy") if same == "copy" else
                 _folder(tmp_path / "mat", names=(TRIAL_02,), layout="mat"))
        message = f"holds trial {TRIAL_02}, the same recording as the scored trial {TRIAL_02}"
    err = _refused(tmp_path, capsys, test, message, "--train", str(train),
                   estimators="madgwick")
    assert err.startswith("attitude-bench: error: train = ")


def test_train_and_tune_are_one_choice(tmp_path, capsys):
    (tmp_path / "train").mkdir()
    (tmp_path / "test").mkdir()
    train, test = _two_datasets(tmp_path)
    _refused(tmp_path, capsys, test, "give one of them", "--train", str(train),
             "--tune", "all-trials", estimators="madgwick")
    _refused(tmp_path, capsys, test, "is not a folder", "--train", str(tmp_path / "nowhere"),
             estimators="madgwick")
    _refused(tmp_path, capsys, test, "--gyro-delay is the scored device's", "--train",
             str(train), "--gyro-delay", "0.004", estimators="madgwick")
