"""Replaying a real gyro against an optical reference (the shipped BROAD trials)."""
import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from benchmarks.cli import main
from benchmarks.experiments.replay import (
    DATASETS,
    open_dataset,
    pseudo_star_tracker,
    replay,
    replay_scenario,
)
from dynamics.quaternion import attitude_error_rad, attitude_error_vector_rad, quat_from_rotvec, \
    quat_multiply
from estimators import DeadReckoning
from sensors.recording import load_recording

#: The trials as the dataset's README describes them: samples, NaN reference rows.
SHIPPED = {"broad-02": (53240, 1706), "broad-07": (52518, 1594)}


@pytest.mark.parametrize("dataset", list(DATASETS))
def test_the_shipped_trials_load_with_their_shapes_rate_and_gaps(dataset):
    recording, attribution = open_dataset(dataset)
    samples, gaps = SHIPPED[dataset]
    assert recording.gyro_radps.shape == (samples, 3)
    assert recording.reference_quat.shape == (samples, 4)
    assert recording.movement.shape == (samples,) and recording.movement.dtype == bool
    assert recording.rate_hz == pytest.approx(2000 / 7)          # 285.714... Hz
    assert (~recording.has_reference).sum() == gaps
    assert "CC BY 4.0" in attribution and "10.3390/data6070072" in attribution
    # The gaps are kept through the replay: no reading inside one, NaN error there.
    start = int(np.argmax(recording.has_reference))
    trimmed = recording.from_sample(start)
    scenario = replay_scenario(trimmed, interval_s=0.1)
    readings = pseudo_star_tracker(trimmed, scenario, seed=0)
    assert not readings.available[~trimmed.has_reference].any()
    assert readings.available[trimmed.has_reference].sum() > 1000


def _dead_reckon(recording, start, steps, right_multiplied=True):
    """The gyro less its rest mean, integrated from the reference at ``start``."""
    rates = recording.gyro_radps[start:start + steps] - recording.rest_gyro_mean_radps()
    if right_multiplied:     # our convention: q̇ = ½ q ⊗ [0, ω], ω in the body frame
        estimator = DeadReckoning(dt=recording.dt, initial_attitude=recording.reference_quat[start])
        return estimator.run(rates, np.tile([1.0, 0, 0, 0], (steps, 1)), np.zeros(steps, bool))
    q, out = recording.reference_quat[start].copy(), []
    for rate in rates:       # the other convention: ω taken in the reference frame
        out.append(q)
        q = quat_multiply(quat_from_rotvec(rate * recording.dt), q)
        q = q / np.linalg.norm(q)
    return np.array(out)


@pytest.mark.parametrize("dataset", list(DATASETS))
def test_the_quaternion_convention_is_ours(dataset):
    # Over the first 10 s of movement (2,857 samples, rates up to hundreds of
    # °/s) dead reckoning with the rest bias removed stays within 5° of the
    # reference (measured: 1.7° on trial 02, 4.3° on 07); with the opposite
    # convention it is off by more than 10° (measured: 10.9° and 149°).
    recording, _ = open_dataset(dataset)
    start, steps = recording.rest_samples.stop, int(10 * recording.rate_hz)
    reference = recording.reference_quat[start:start + steps]
    ours = np.degrees(attitude_error_rad(reference, _dead_reckon(recording, start, steps)))
    other = np.degrees(attitude_error_rad(reference, _dead_reckon(recording, start, steps,
                                                                  right_multiplied=False)))
    assert np.nanmax(ours) < 5.0
    assert np.nanmax(other) > 10.0


def test_the_pseudo_star_tracker_has_the_requested_sigma():
    # Each reading's error rotation θ (3 axes) is N(0, σ² I): Σ θ²/σ² over n
    # readings is χ²(3n). Two-sided 99.9 % band; the same statistic with the
    # σ 10 % off must fall outside it (the test can fail).
    recording, _ = open_dataset("broad-02")
    recording = recording.from_sample(int(np.argmax(recording.has_reference)))
    sigma_deg = 0.1
    scenario = replay_scenario(recording, interval_s=0.05, noise_deg=sigma_deg)
    readings = pseudo_star_tracker(recording, scenario, seed=3)
    taken = readings.available
    theta = attitude_error_vector_rad(recording.reference_quat[taken], readings.quat[taken])
    n = 3 * taken.sum()
    low, high = chi2.ppf([0.0005, 0.9995], n)
    statistic = lambda sigma: np.sum(theta ** 2) / np.radians(sigma) ** 2  # noqa: E731
    assert low < statistic(sigma_deg) < high, (low, statistic(sigma_deg), high)
    assert not low < statistic(1.1 * sigma_deg) < high
    assert not low < statistic(0.9 * sigma_deg) < high


@pytest.mark.slow      # the per-run MEKF over the whole trial, 52,000 steps: 8 s
def test_the_mekf_finds_the_real_bias_on_trial_02():
    # The gyro's mean over the initial rest is its switch-on bias (about
    # 0.2 °/s per axis). Scale and misalignment errors move the estimate while
    # the IMU turns, but after the movement, at rest again, the MEKF's final
    # bias is within 0.05 °/s (a quarter of the bias) of it on every axis
    # (measured: 0.015 °/s). Dead reckoning on the raw gyro drifts past 40°.
    result = replay("broad-02", ("dead-reckoning", "mekf"))
    final = np.degrees(result.run.traces["mekf"].bias_radps[-1])
    rest = np.degrees(result.rest_bias_radps)
    assert np.abs(rest).min() > 0.1
    assert np.abs(final - rest).max() < 0.05, (final, rest)
    summary = result.summary().set_index("estimator")
    assert summary.loc["dead-reckoning", "final_deg"] > 40.0
    assert summary.loc["mekf", "rms_movement_deg"] < 2.0


def _user_recording(tmp_path, **changes):
    """8,000 samples of trial 02 (the last 1.6 s of its rest, then 26 s of
    movement) as a user's own file, with ``changes`` (None drops a key)."""
    recording, _ = open_dataset("broad-02")
    keep = slice(11000, 19000)     # the end of the rest and 26 s of movement
    data = {"imu_gyr_radps": recording.gyro_radps[keep],
            "opt_quat": recording.reference_quat[keep],
            "movement": recording.movement[keep],
            "sampling_rate_hz": np.array(recording.rate_hz)}
    data.update(changes)
    for key in [k for k, v in changes.items() if v is None]:
        del data[key]
    path = tmp_path / "mine.npz"
    np.savez(path, **data)
    return path


def test_replay_writes_figure_and_summary_for_a_users_recording(tmp_path, capsys):
    path = _user_recording(tmp_path)
    assert main(["replay", "--dataset", str(path), "--estimators", "dead-reckoning,mekf",
                 "--star-tracker-interval", "0.5", "--out", str(tmp_path / "o"),
                 "--quiet"]) == 0
    summary = pd.read_csv(tmp_path / "o" / "summary.csv")
    assert list(summary["estimator"]) == ["dead-reckoning", "mekf"]
    assert list(summary.columns) == ["estimator", "rms_movement_deg", "mean_deg", "max_deg",
                                     "final_deg", "final_bias_error_degps"]
    assert (tmp_path / "o" / "replay.png").stat().st_size > 10_000
    assert not (tmp_path / "o" / "ATTRIBUTION.txt").exists()     # the user's own data
    assert "every 0.5005 s" in capsys.readouterr().out           # rounded to 143 samples


def test_a_recording_that_moves_from_its_first_sample_replays(tmp_path, capsys):
    """No initial rest: the gyro's noise is the IMU filters' default, not the
    variance of no samples (0, a filter sure of its gyro), the bias panels
    have no rest mean to draw (it is NaN: the figure's range must not be),
    and the summary's bias error is NaN, not a number against nothing."""
    from estimators.imu import GYRO_NOISE_DENSITY
    moving = np.ones(8000, dtype=bool)
    path = _user_recording(tmp_path, movement=moving)
    recording, _ = open_dataset(str(path))
    assert recording.rest_samples == slice(0, 0)
    scenario = replay_scenario(recording, 0.5)
    assert scenario.gyro_noise == GYRO_NOISE_DENSITY ** 2
    assert main(["replay", "--dataset", str(path), "--estimators", "dead-reckoning,mekf",
                 "--out", str(tmp_path / "o"), "--quiet"]) == 0
    summary = pd.read_csv(tmp_path / "o" / "summary.csv").set_index("estimator")
    assert np.isnan(summary.loc["mekf", "final_bias_error_degps"])
    assert summary.loc["mekf", "rms_movement_deg"] < 2.0
    assert (tmp_path / "o" / "replay.png").stat().st_size > 10_000


@pytest.mark.slow      # 3.5 s
def test_a_shipped_replay_carries_the_attribution(tmp_path):
    assert main(["replay", "--dataset", "broad-07", "--estimators", "dead-reckoning",
                 "--out", str(tmp_path), "--quiet"]) == 0
    assert "CC BY 4.0" in (tmp_path / "ATTRIBUTION.txt").read_text()


@pytest.mark.parametrize("changes, message", [
    ({"movement": None}, "has no key 'movement'"),
    ({"imu_gyr_radps": np.zeros((8000, 2))}, "imu_gyr_radps has shape (8000, 2)"),
    ({"opt_quat": np.zeros((10, 4))}, "opt_quat has shape (10, 4); must be (8000, 4)"),
    ({"opt_quat": np.tile([2.0, 0, 0, 0], (8000, 1))}, "unit quaternions [w, x, y, z]; row 0 "
                                                       "has norm 2"),
    ({"sampling_rate_hz": np.array(0.0)}, "sampling_rate_hz = 0.0 must be one positive"),
    ({"sampling_rate_hz": np.array(-285.0)}, "must be one positive number"),
    ({"imu_gyr_radps": np.full((8000, 3), np.nan)}, "imu_gyr_radps must be finite; row 0"),
    ({"opt_quat": np.full((8000, 4), np.nan)}, "has no reference attitude"),
    ({"movement": np.zeros(8000, dtype=bool)}, "nothing to score: it never moves"),
    ({"opt_quat": np.where(np.arange(8000)[:, None] < 400, [[1.0, 0, 0, 0]], np.nan)},
     "nothing to score: it has no reference during its movement"),
])
def test_bad_recordings_are_refused_in_one_line(tmp_path, capsys, changes, message):
    path = _user_recording(tmp_path, **changes)
    assert main(["replay", "--dataset", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"attitude-bench: error: dataset = '{path}': ")
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, message", [
    (["--dataset", "broad-99"], "must be one of broad-02, broad-07, a path to a .npz recording or a [recording] .toml"),
    (["--dataset", "missing.npz"], "file does not exist"),
    (["--star-tracker-interval", "0"], "star_tracker_interval = 0.0: must be > 0"),
    (["--star-tracker-noise-deg", "-1"], "star_tracker_noise_deg = -1.0: must be > 0"),
    (["--star-tracker-noise-deg", "0"], "star_tracker_noise_deg = 0.0: must be > 0"),
    (["--star-tracker-interval", "1000"],
     "must be shorter than the recording (186.3 s; --star-tracker-interval, 1 s by default)"),
    (["--estimators", "ekf,ekf"], "names ekf more than once"),
])
def test_bad_replay_settings_are_refused_in_one_line(tmp_path, capsys, argv, message):
    assert main(["replay", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_a_file_that_is_not_an_archive_is_refused(tmp_path, capsys):
    path = tmp_path / "junk.npz"
    path.write_text("not a zip")
    assert main(["replay", "--dataset", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "must be a numpy .npz archive (a zip file); this file is not one" in \
        capsys.readouterr().err
    with pytest.raises(ValueError, match="must be a numpy .npz archive"):
        load_recording(path)


def test_a_settings_file_overrides_what_the_recording_sets(tmp_path, capsys):
    from benchmarks.experiments.replay import load_replay
    path = _user_recording(tmp_path)
    settings = tmp_path / "settings.toml"
    settings.write_text("[estimators.mekf]\ngyro_noise = 1e-5\n"
                        "[estimators.ekf]\npc_exponent = -16.0\n")
    derived, overridden = load_replay(str(path)), load_replay(str(path), settings=settings)
    assert overridden.scenario.pc_exponent == -16.0 != derived.scenario.pc_exponent
    mekf = overridden.scenario.estimator_options["mekf"]
    assert mekf["gyro_noise"] == 1e-5
    assert mekf["initial_bias_sigma_radps"] == derived.scenario.estimator_options["mekf"][
        "initial_bias_sigma_radps"]                       # the derived ones are kept
    settings.write_text("tstop = 5\n")
    assert main(["replay", "--dataset", str(path), "--scenario", str(settings),
                 "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == ("attitude-bench: error: tstop = 5: only "
                                       "[estimators.NAME] sections may be given here; the "
                                       "rest is set for you\n")
    assert not (tmp_path / "o").exists()


def test_a_rest_before_the_reference_begins_is_the_rest(tmp_path):
    # A logger's recording at rest for 5 s, moving from then on, its
    # reference from 7 s: the rest found (VQF's, from the first sample) is
    # where the gyro's bias and noise are taken, not everything before the
    # reference (which took the turning of 5-7 s for a bias of 20 deg/s, and
    # left the filters the default noise).
    import math
    import pandas as pd
    from benchmarks.experiments.replay import load_replay
    from dynamics.handheld import HandheldMotion
    from sensors.handheld import simulated_recording
    recording = simulated_recording(2, HandheldMotion(rate_hz=200.0, rest_s=5.0, moving_s=25.0,
                                                      final_rest_s=2.0))
    n = recording.n_samples
    frame = pd.DataFrame({"t": np.arange(n) / 200.0})
    for i, axis in enumerate("xyz"):
        frame["g" + axis] = recording.gyro_radps[:, i]
        frame["a" + axis] = recording.accelerometer_mps2[:, i]
    reference = recording.reference_quat.copy()
    reference[:7 * 200] = np.nan
    for i, part in enumerate("wxyz"):
        frame["q" + part] = reference[:, i]
    frame.to_csv(tmp_path / "log.csv", index=False)
    (tmp_path / "log.toml").write_text(
        '[recording]\nfile = "log.csv"\n[recording.gyro]\ntime = "t"\n'
        'columns = ["gx", "gy", "gz"]\nunit = "rad/s"\n[recording.accelerometer]\ntime = "t"\n'
        'columns = ["ax", "ay", "az"]\nunit = "m/s^2"\n[recording.reference]\ntime = "t"\n'
        'columns = ["qw", "qx", "qy", "qz"]\norder = "wxyz"\n')
    with pytest.warns(UserWarning, match="are at rest"):
        data = load_replay(str(tmp_path / "log.toml"))
    at_rest = recording.gyro_radps[:4 * 200].mean(axis=0)       # well inside the rest
    assert np.abs(np.degrees(data.rest_bias_radps - at_rest)).max() < 0.02
    noise = float(np.mean(recording.gyro_radps[:4 * 200].var(axis=0))) * recording.dt
    assert data.scenario.gyro_noise == pytest.approx(noise, rel=0.2)
    assert math.isfinite(data.scenario.gyro_noise)


@pytest.mark.slow          # 40 s: a tuning of the EKF by its likelihood
def test_a_training_recording_with_nothing_to_score_still_tunes_by_likelihood(tmp_path):
    # Tuning by the innovations' likelihood reads no reference: a training
    # recording that never moves is one to tune on (the scored recording is
    # refused where it has nothing to score, not the training one).
    (tmp_path / "train").mkdir()
    (tmp_path / "test").mkdir()
    train = _user_recording(tmp_path / "train", movement=np.zeros(8000, dtype=bool))
    test = _user_recording(tmp_path / "test")
    argv = ["replay", "--dataset", str(test), "--estimators", "ekf", "--tuned", "likelihood",
            "--train-dataset", str(train), "--out", str(tmp_path / "o"), "--quiet"]
    assert main(argv) == 0
    assert (tmp_path / "o" / "summary.csv").exists()
