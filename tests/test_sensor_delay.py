"""A magnetometer that reads late against its gyro: the delay fitted from
how the field turns (no reference read), the readings taken at their
samples' times, and ``broad --magnetometer-delay``."""
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Slerp
from scipy.stats import chi2

from benchmarks.broad import trial_notes
from benchmarks.broad.dataset import open_broad
from benchmarks.broad.inputs import imu_inputs
from benchmarks.broad.metric import rmse_deg
from benchmarks.cli import main
from benchmarks.engine.recorded import run_recorded
from benchmarks.shipped import shipped_file
from dynamics.handheld import HandheldMotion
from dynamics.quaternion import to_rotation
from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator
from sensors.delay import (JACKKNIFE_BLOCKS, at_sample_times, delay_fit, described,
                           hard_iron_at)
from sensors.handheld import HandheldImu, simulated_recording

SHIPPED = shipped_file("datasets/broad/trials.json").parent
#: A brisk hand-held motion: 40 s at 200 Hz, turning 150 °/s RMS per axis.
MOTION = HandheldMotion(rate_hz=200.0, rest_s=2.0, moving_s=36.0, final_rest_s=2.0,
                        rate_rms_dps=150.0, bandwidth_hz=2.0)
IMU = HandheldImu()


def late_field(recording, delay_s: float, offset=np.zeros(3)) -> np.ndarray:
    """The field as a magnetometer ``delay_s`` late reads it: the body's
    attitude at ``t - delay_s`` (the truth, interpolated), plus ``offset``
    (a hard iron) and the IMU's noise."""
    t = np.arange(recording.n_samples) * recording.dt
    truth = Slerp(t, to_rotation(recording.reference_quat))
    at = np.clip(t - delay_s, 0.0, t[-1])
    rng = np.random.default_rng(7)
    return (truth(at).inv().apply(IMU.field_world()) + offset
            + IMU.magnetometer_sigma_uT * rng.standard_normal((len(t), 3)))


@pytest.fixture(scope="module")
def brisk():
    return simulated_recording(3, MOTION, IMU)


def _fit(recording, field):
    return delay_fit(recording.gyro_radps, field, np.ones(len(field), dtype=bool),
                     recording.dt)


@settings(max_examples=6, deadline=None, derandomize=True)
@given(delay_ms=st.floats(-40.0, 40.0))
def test_the_fit_finds_the_delay_a_magnetometer_was_given(brisk, delay_ms):
    # Within a millisecond (a fifth of a 5 ms sample) and within five of its
    # own standard errors, wherever the delay lies in ±40 ms; no reference read.
    fit = _fit(brisk, late_field(brisk, delay_ms / 1e3))
    assert fit is not None
    assert abs(fit.delay_s * 1e3 - delay_ms) < 1.0
    assert abs(fit.delay_s * 1e3 - delay_ms) < 5 * fit.standard_error_s * 1e3 + 0.2
    if abs(delay_ms) > 5.0:
        assert fit.clear(brisk.dt)


def test_a_gyro_that_reads_the_interval_after_each_sample_is_a_sample_early(brisk):
    # The delay is the one the filters see: against a gyro whose readings are
    # the rate over the interval after them, an on-time field reads one
    # sample (5 ms) late.
    after = replace(brisk, gyro_radps=np.vstack([brisk.gyro_radps[1:], brisk.gyro_radps[-1:]]))
    assert abs(_fit(after, late_field(after, 0.0)).delay_s - brisk.dt) < 1e-3


@pytest.mark.slow        # 5-6 s: three simulated recordings' delay fits
def test_the_simulated_magnetometer_is_on_time_against_its_gyro():
    # The simulated IMU's gyro reads the interval before each sample, as the
    # filters take it (sensors.handheld): its own field is on time. It had
    # read the interval after, and every filter integrated it a sample late.
    for seed in range(3):
        recording = simulated_recording(seed)
        fit = _fit(recording, recording.magnetometer_uT)
        assert abs(fit.delay_s) < 1e-3 and not fit.clear(recording.dt)


def test_a_hard_iron_is_fitted_with_the_delay(brisk):
    offset = np.array([12.0, -6.0, 25.0])
    fit = _fit(brisk, late_field(brisk, 0.0125, offset))
    assert abs(fit.delay_s - 0.0125) < 1e-3
    assert np.allclose(fit.offset, offset, atol=1.0)


def test_an_on_time_magnetometer_is_not_clearly_late(brisk):
    # The check can fail: a magnetometer on time fits near zero, and is not
    # said to be late.
    fit = _fit(brisk, late_field(brisk, 0.0))
    assert abs(fit.delay_s) < 1e-3
    assert not fit.clear(brisk.dt)
    assert _fit(brisk, late_field(brisk, 0.02)).clear(brisk.dt)


def test_a_recording_that_does_not_turn_is_not_timed():
    still = simulated_recording(0, replace(MOTION, rate_rms_dps=0.0), IMU)
    assert _fit(still, late_field(still, 0.02)) is None


def test_the_readings_taken_at_their_times_are_the_fields_then(brisk):
    # Turned by the gyro over the delay, 20 ms late readings are the field at
    # their samples' times up to the noise (the gyro's bias and scale errors
    # over 20 ms are far below it); as they were, degrees off.
    on_time = late_field(brisk, 0.0)
    late = late_field(brisk, 0.02)
    moving = brisk.movement
    before = np.sqrt(np.mean(np.sum((late - on_time)[moving] ** 2, axis=1)))
    timed = at_sample_times(brisk.gyro_radps, late, np.ones(len(late), dtype=bool), brisk.dt,
                            0.02)
    after = np.sqrt(np.mean(np.sum((timed - on_time)[moving] ** 2, axis=1)))
    assert before > 1.5
    assert after < 0.25 * before


def test_a_reading_that_is_not_there_is_kept_as_it_is(brisk):
    late = late_field(brisk, 0.02)
    read = np.arange(len(late)) % 4 == 0
    late[~read] = 0.0
    timed = at_sample_times(brisk.gyro_radps, late, read, brisk.dt, 0.02)
    assert np.array_equal(timed[~read], late[~read])
    assert not np.array_equal(timed[read], late[read])


def test_broads_shipped_magnetometer_reads_about_13_ms_late():
    # Measured here, each trial alone: BROAD's magnetometer reads 11.8 to
    # 14.1 ms after its gyro on all 30 trials; the two shipped ones 13.5 and 12.8.
    dataset = open_broad(SHIPPED)
    for trial in dataset.available:
        recording = dataset.load(trial)
        field = recording.magnetometer_uT
        fit = delay_fit(recording.gyro_radps, field, np.any(field != 0.0, axis=1),
                        recording.dt)
        assert 0.0115 < fit.delay_s < 0.0145
        assert fit.clear(recording.dt)


def test_the_dataset_takes_each_reading_at_its_time_only_when_asked():
    dataset = open_broad(SHIPPED)
    trial = dataset.available[1]
    raw = dataset.load(trial).magnetometer_uT
    auto = replace(dataset, magnetometer_delay="auto").load(trial).magnetometer_uT
    given_delay = replace(dataset, magnetometer_delay=0.0128).load(trial).magnetometer_uT
    assert not np.array_equal(auto, raw)
    # the fitted delay is 12.8 ms: a number close to it takes nearly the same readings
    assert np.max(np.abs(auto - given_delay)) < 0.5
    assert np.max(np.abs(auto - raw)) > 5.0
    # the recording's own channel, writable as every channel is (the timed
    # readings kept for the offline estimators are read-only and shared)
    assert auto.flags.writeable


@pytest.mark.parametrize("delay", [0.005, "auto"])
def test_a_field_timed_by_the_dataset_is_not_timed_again(delay):
    # --magnetometer-delay, given or fitted, times the field for every
    # estimator: the offline ones, which would time it themselves, read it
    # as it is, and a delay given is the one they read (none taken out twice)
    dataset = open_broad(SHIPPED)
    trial = dataset.available[1]
    for timed, recording in ((False, dataset.load(trial)),
                             (True, replace(dataset, magnetometer_delay=delay).load(trial))):
        assert recording.magnetometer_timed is timed
        inputs = imu_inputs(recording)
        for name in ("mekf-smoother", "vqf-offline"):
            estimator = resolve_estimator(name).from_scenario(inputs.scenario)
            assert estimator.fit_magnetometer_delay is not timed
        run = run_recorded(estimator, inputs.sensors.omega_meas_radps, inputs.sensors.vectors)
        assert (run.magnetometer_delay_s is None) is timed
    # the other settings of a section stay (the smoother's are the MEKF's)
    smoother = resolve_estimator("mekf-smoother").from_scenario(inputs.scenario)
    assert smoother.magnetometer_model == "heading" and smoother.rest_updates


@pytest.fixture(scope="module")
def mekf_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("delay")
    codes = {}
    for delay in ("0", "auto"):
        codes[delay] = main(["broad", "--trials", "07", "--estimators", "mekf,vqf-offline",
                             "--magnetometer-delay", delay, "--out", str(root / delay),
                             "--quiet"])
    return codes, {delay: pd.read_csv(root / delay / "broad_trials.csv")
                   for delay in ("0", "auto")}


@pytest.mark.slow      # broad on trial 07 twice: 5 s
def test_broad_with_the_delay_fitted_scores_the_readings_at_their_times(mekf_runs):
    codes, tables = mekf_runs
    assert codes == {"0": 0, "auto": 0}
    before = tables["0"].set_index("estimator")["total_rmse_deg"]
    after = tables["auto"].set_index("estimator")["total_rmse_deg"]
    # Offline VQF times its field itself (fit_magnetometer_delay): the
    # readings `auto` timed, fitted again, are on time, and nothing changes
    # (measured here on trial 07: 1.332° both); the online MEKF reads them as given.
    assert abs(after["vqf-offline"] - before["vqf-offline"]) < 0.005
    assert after["mekf"] != before["mekf"]
    # and the trial table says what each took out: 12.8 ms once, never twice
    taken = {delay: table.set_index("estimator")["magnetometer_delay_ms"]
             for delay, table in tables.items()}
    assert 12.0 < taken["0"]["vqf-offline"] < 13.6
    assert np.isnan([taken["0"]["mekf"], taken["auto"]["mekf"],
                     taken["auto"]["vqf-offline"]]).all()


def _offline_run(recording, name, fit):
    inputs = imu_inputs(recording)
    estimator = resolve_estimator(name).from_scenario(inputs.scenario,
                                                      fit_magnetometer_delay=fit)
    run = run_recorded(estimator, inputs.sensors.omega_meas_radps, inputs.sensors.vectors)
    return run, rmse_deg(run.estimates, recording.reference_quat,
                         recording.movement)["total_rmse_deg"]


@pytest.mark.parametrize("name", [pytest.param("mekf-smoother", marks=pytest.mark.slow),
                                  "vqf-offline"])
def test_an_offline_estimator_times_its_field_itself(name):
    # Measured here (total RMSE, without → with the fit): trial 02 the smoother
    # 0.918° → 0.800°, offline VQF 1.014° → 0.882°; trial 07 1.331° → 1.327°
    # and 1.710° → 1.332°. The delay is BROAD's (11.8–14.1 ms on its 30 trials).
    dataset = open_broad(SHIPPED)
    for trial in dataset.available:
        recording = dataset.load(trial)
        untimed, before = _offline_run(recording, name, False)
        timed, after = _offline_run(recording, name, True)
        assert untimed.magnetometer_delay_s is None
        assert 0.0115 < timed.magnetometer_delay_s < 0.0145
        assert after < before
        # the same readings as `--magnetometer-delay auto` gives every estimator
        auto = replace(dataset, magnetometer_delay="auto").load(trial)
        _, given_timed = _offline_run(auto, name, False)
        assert abs(given_timed - after) < 0.005


@pytest.mark.parametrize("given_delay, message", [
    ("0.2", "'0.2': must be auto or seconds within ±0.1"),
    ("soon", "'soon': must be auto or seconds within ±0.1"),
    ("nan", "'nan': must be auto or seconds within ±0.1"),
])
def test_a_bad_delay_is_refused_in_one_line(tmp_path, capsys, given_delay, message):
    assert main(["broad", "--magnetometer-delay", given_delay, "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_the_case_study_refuses_a_delay(tmp_path, capsys):
    assert main(["broad", "--case-study", "--magnetometer-delay", "auto", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    assert "--magnetometer-delay does not apply to --case-study" in capsys.readouterr().err


@pytest.mark.parametrize("delay, said", [
    ("0", "reads 12.8 ± 0.1 ms late against the gyro (fitted from how the field turns as the "
          "gyro says); --magnetometer-delay auto takes each reading at its sample's time "
          "for every estimator (the offline ones do so by default)"),
    ("auto", "reads 12.8 ± 0.1 ms late against the gyro (fitted from how the field turns as "
             "the gyro says): each reading taken at its sample's time"),
])
def test_the_delay_is_said_once_the_inputs_are_checked(tmp_path, capsys, monkeypatch, delay,
                                                       said):
    monkeypatch.setattr(trial_notes, "_NOTED", set())
    assert main(["broad", "--trials", "07", "--estimators", "mekf", "--magnetometer-delay",
                 delay, "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert said in capsys.readouterr().err
    # a refusal after the trial is read is its one line, the note unsaid
    monkeypatch.setattr(trial_notes, "_NOTED", set())
    assert main(["broad", "--trials", "07", "--estimators", "mekf", "--magnetometer-delay",
                 delay, "--gyro-delay", "1", "--out", str(tmp_path / "bad"), "--quiet"]) == 2
    err = capsys.readouterr().err
    refusal = "gyro_delay = 1.0" if delay == "0" else "--gyro-delay moves the gyro"
    assert len(err.strip().splitlines()) == 1 and refusal in err, err


@pytest.mark.slow        # 6-7 s: a local Dask cluster's start
def test_a_workers_notes_are_said_as_the_commands_own(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(trial_notes, "_NOTED", set())
    # Run on a Dask worker, a trial's notes come back with its results and
    # are said as the command says them: not printed raw in the worker's
    # process, file and line first.
    assert main(["broad", "--trials", "07", "--estimators", "mekf", "--workers", "1",
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "note: trial 07_undisturbed_fast_rotation_B: its magnetometer reads 12.8" in err, err
    assert "UserWarning" not in err and "benchmark.py" not in err


def test_gaps_in_the_readings_leave_the_fit_as_it_was(brisk):
    # A pair across a gap would turn too far for the first order: left out.
    late = late_field(brisk, 0.03)
    read = np.ones(len(late), dtype=bool)
    for start, seconds in ((1000, 0.5), (2500, 1.0), (4000, 2.0), (6000, 3.0)):
        read[start:start + int(seconds / brisk.dt)] = False
    whole = _fit(brisk, late)
    gapped = delay_fit(brisk.gyro_radps, np.where(read[:, None], late, 0.0), read, brisk.dt)
    assert abs(gapped.delay_s - 0.03) < 1e-3 and abs(whole.delay_s - 0.03) < 1e-3
    assert np.allclose(gapped.offset, 0.0, atol=0.5)


@pytest.mark.slow
def test_the_stated_error_is_the_fits_scatter(brisk):
    # Over 48 draws of the magnetometer's noise (σ 2 µT) the fit scatters as
    # its stated error says. The RMS of n errors over their σ is √(χ²_n / n):
    # within [0.743, 1.266] at 99 % for n = 48 (scipy's χ² quantiles), the
    # band widened by the stated error's own scatter (the mean of n
    # jackknife errors over 20 stretches: relative σ 1/√(2·19·n), three of
    # them). A stated error half or twice the true one falls outside it.
    errors, stated = [], []
    noisy = replace(IMU, magnetometer_sigma_uT=2.0)
    t = np.arange(brisk.n_samples) * brisk.dt
    truth = Slerp(t, to_rotation(brisk.reference_quat))
    field = truth(np.clip(t - 0.03, 0.0, t[-1])).inv().apply(noisy.field_world())
    draws = 48
    for seed in range(draws):
        rng = np.random.default_rng(100 + seed)
        fit = _fit(brisk, field + 2.0 * rng.standard_normal(field.shape))
        errors.append(fit.delay_s - 0.03)
        stated.append(fit.standard_error_s)
    spread = 3.0 / math.sqrt(2 * (JACKKNIFE_BLOCKS - 1) * draws)
    low, high = np.sqrt(chi2.ppf([0.005, 0.995], draws) / draws) * [1 - spread, 1 + spread]
    ratio = np.sqrt(np.mean(np.square(errors))) / np.mean(stated)
    assert low < ratio < high, (ratio, low, high)
    assert not low < ratio / 2 < high and not low < ratio * 2 < high


def test_a_delay_beyond_the_search_is_never_clear(brisk):
    # Readings 0.3 s late: no delay within ±0.1 s explains their turning,
    # and the fit says so rather than naming one.
    fit = _fit(brisk, late_field(brisk, 0.3))
    assert not fit.clear(brisk.dt)
    assert fit.beyond or fit.unexplained >= 1.0
    assert "check its timestamps" in described(fit, brisk.dt)
    assert "too little" in described(None, brisk.dt)
    # a fit with no best delay (its share not curved upward there) gives no
    # error to print: said so, never "± inf ms"
    flat = replace(fit, beyond=False, unexplained=0.5, standard_error_s=math.inf)
    assert "no clear best delay" in described(flat, brisk.dt) and not flat.clear(brisk.dt)


def test_a_gyro_delay_with_a_magnetometer_delay_is_refused(tmp_path, capsys):
    assert main(["broad", "--trials", "07", "--gyro-delay", "0.004", "--magnetometer-delay",
                 "auto", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--gyro-delay moves the gyro: give one of them" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_stuck_or_unreadable_magnetometer_is_not_timed(brisk):
    read = np.ones(brisk.n_samples, dtype=bool)
    stuck = np.tile([20.0, 5.0, -40.0], (brisk.n_samples, 1))
    assert delay_fit(brisk.gyro_radps, stuck, read, brisk.dt) is None
    broken = late_field(brisk, 0.01)
    broken[100] = np.nan
    assert delay_fit(brisk.gyro_radps, broken, read, brisk.dt) is None


def test_a_slower_magnetometer_is_paired_20_ms_apart(brisk):
    # A magnetometer at a quarter of the gyro's rate: its pairs are about
    # 20 ms apart in time, not 20 readings, and the delay is found as well.
    read = np.arange(brisk.n_samples) % 4 == 0
    late = np.where(read[:, None], late_field(brisk, 0.025), 0.0)
    fit = delay_fit(brisk.gyro_radps, late, read, brisk.dt)
    assert abs(fit.delay_s - 0.025) < 1e-3 and fit.clear(brisk.dt)


def test_readings_are_turned_about_their_hard_iron(brisk):
    # A hard iron turns with the body: the readings are turned about it, and
    # a delay given in seconds is turned about the one fitted at it.
    offset = np.array([30.0, -20.0, 45.0])
    read = np.ones(brisk.n_samples, dtype=bool)
    late, on_time = late_field(brisk, 0.02, offset), late_field(brisk, 0.0, offset)
    found = hard_iron_at(brisk.gyro_radps, late, read, brisk.dt, 0.02)
    assert np.allclose(found, offset, atol=1.0)
    rms = lambda a: np.sqrt(np.mean(np.sum((a - on_time)[brisk.movement] ** 2, axis=1)))
    timed = at_sample_times(brisk.gyro_radps, late, read, brisk.dt, 0.02, found)
    assert rms(timed) < 0.25 * rms(late)
    about_zero = at_sample_times(brisk.gyro_radps, late, read, brisk.dt, 0.02)
    assert rms(about_zero) > 2 * rms(timed)


def test_the_dataset_checks_its_delay_and_keeps_what_it_applied():
    dataset = open_broad(SHIPPED)
    assert replace(dataset, magnetometer_delay="Auto").magnetometer_delay == "auto"
    with pytest.raises(InvalidParameterError, match="magnetometer_delay = 0.5: must be auto"):
        replace(dataset, magnetometer_delay=0.5)
    trial = dataset.available[1]
    replace(dataset, magnetometer_delay="auto").load(trial)
    fit = trial_notes.applied_delay(dataset.files[trial], trial)
    assert fit is not None and 0.0115 < fit.delay_s < 0.0145
    dataset.load(trial)                          # loaded as it is: nothing applied
    assert trial_notes.applied_delay(dataset.files[trial], trial) is None


def _phone_log(folder, delay_s: float) -> str:
    """A phone-like log: a 200 Hz gyro (each reading the mean rate over the
    interval before it), accelerometer and reference on its clock, and a 50 Hz
    magnetometer on its own clock, ``delay_s`` late: the truth a hand-held
    motion simulated at 1 kHz."""
    from dynamics.handheld import simulate_handheld
    truth = simulate_handheld(HandheldMotion(rate_hz=1000.0, rest_s=2.0, moving_s=36.0,
                                             final_rest_s=2.0, rate_rms_dps=120.0,
                                             bandwidth_hz=1.5), np.random.default_rng(5))
    t = np.arange(len(truth.q_true)) / 1000.0
    turn = Slerp(t, to_rotation(truth.q_true))
    at = lambda times: turn(np.clip(times, 0.0, t[-1]))
    rng = np.random.default_rng(6)
    tg = np.arange(1, int(39.5 * 200)) / 200.0
    now = at(tg)
    gyro = (at(tg - 0.005).inv() * now).as_rotvec() / 0.005 + 3e-3 * rng.standard_normal(
        (len(tg), 3))
    acc = np.column_stack([np.interp(tg, t, truth.acceleration_mps2[:, i]) for i in range(3)])
    acc = now.inv().apply(acc + [0.0, 0.0, 9.80665]) + 0.03 * rng.standard_normal((len(tg), 3))
    tm = 0.0013 + np.arange(int(39.4 * 50)) / 50.0
    field = at(tm - delay_s).inv().apply(IMU.field_world()) + 0.3 * rng.standard_normal(
        (len(tm), 3))
    folder.mkdir()
    pd.DataFrame({"t": tg, **{f"g{a}": gyro[:, i] for i, a in enumerate("xyz")},
                  **{f"a{a}": acc[:, i] for i, a in enumerate("xyz")},
                  **{f"q{a}": now.as_quat()[:, "xyzw".index(a)] for a in "wxyz"}}
                 ).to_csv(folder / "log.csv", index=False)
    pd.DataFrame({"t": tm, **{f"m{a}": field[:, i] for i, a in enumerate("xyz")}}
                 ).to_csv(folder / "mag.csv", index=False)
    (folder / "log.toml").write_text(
        '[recording]\nfile = "log.csv"\n'
        '[recording.gyro]\ntime = "t"\ncolumns = ["gx", "gy", "gz"]\nunit = "rad/s"\n'
        '[recording.accelerometer]\ntime = "t"\ncolumns = ["ax", "ay", "az"]\nunit = "m/s^2"\n'
        '[recording.magnetometer]\nfile = "mag.csv"\ntime = "t"\ncolumns = ["mx", "my", "mz"]\n'
        'unit = "uT"\n'
        '[recording.reference]\ntime = "t"\ncolumns = ["qw", "qx", "qy", "qz"]\norder = "wxyz"\n')
    return str(folder / "log.toml")


@pytest.mark.slow      # 5 s
def test_a_phones_late_magnetometer_taken_at_its_times_helps_the_mekf(tmp_path, capsys,
                                                                       monkeypatch):
    # A 50 Hz magnetometer 40 ms late on its own clock: the default run notes
    # the delay (with the readings' placement at the next 5 ms gyro sample,
    # 2.5 ms on average), and with auto the MEKF's error falls by a third or more.
    monkeypatch.setattr(trial_notes, "_NOTED", set())
    toml = _phone_log(tmp_path / "phone", 0.04)
    scores = {}
    for delay in ("0", "auto"):
        assert main(["broad", "--broad", toml, "--estimators", "mekf", "--magnetometer-delay",
                     delay, "--out", str(tmp_path / delay), "--quiet"]) == 0
        scores[delay] = pd.read_csv(tmp_path / delay / "broad_trials.csv")[
            "total_rmse_deg"].iloc[0]
        if delay == "0":
            import re
            found = re.search(r"its magnetometer reads ([0-9.]+) ± ([0-9.]+) ms late",
                              capsys.readouterr().err)
            assert found and 41.0 < float(found[1]) < 44.5, found
    assert scores["auto"] < 0.67 * scores["0"], scores


def test_the_field_timing_is_a_setting_of_the_offline_estimators_only():
    from estimators import MekfSmoother, MultiplicativeEKF
    for name in ("mekf-smoother", "vqf-offline"):
        cls = resolve_estimator(name)
        assert cls.constructor_defaults()["fit_magnetometer_delay"] is True
        assert cls(fit_magnetometer_delay=False).fit_magnetometer_delay is False
        with pytest.raises(InvalidParameterError, match="fit_magnetometer_delay = 'yes'"):
            cls(fit_magnetometer_delay="yes")
    # the smoother keeps every MEKF setting beside its own, each declared once
    assert MekfSmoother.option_names() == (*MultiplicativeEKF.option_names(),
                                           "fit_magnetometer_delay")
    for name in ("mekf", "usque", "vqf"):
        assert "fit_magnetometer_delay" not in resolve_estimator(name).option_names()


def test_a_timed_field_is_kept_by_its_contents():
    # A tuning runs each recording many times: the fit is kept, by what the
    # readings hold (a changed reading is fitted anew, never served the old).
    from benchmarks.engine.recorded import field_timed
    dataset = open_broad(SHIPPED)
    inputs = imu_inputs(dataset.load(dataset.available[1]))
    smoother = resolve_estimator("mekf-smoother").from_scenario(inputs.scenario)
    omega, vectors = inputs.sensors.omega_meas_radps, tuple(inputs.sensors.vectors)
    first, fit = field_timed(smoother, omega, vectors)
    again, kept = field_timed(smoother, omega.copy(), tuple(replace(v) for v in vectors))
    assert kept is fit and all(a.body is b.body for a, b in zip(first, again))
    late = tuple(replace(v, body=np.roll(v.body, 3, axis=0)) if v.sensor == "magnetometer"
                 else v for v in vectors)
    _, later = field_timed(smoother, omega, late)
    # three samples (10.5 ms) later still
    assert later.delay_s - fit.delay_s == pytest.approx(3 * inputs.recording.dt, abs=1e-3)


def test_the_timed_fields_kept_stay_within_their_bytes(monkeypatch):
    from sensors import delay
    dataset = open_broad(SHIPPED)
    inputs = imu_inputs(dataset.load(dataset.available[1]))
    field = next(v for v in inputs.sensors.vectors if v.sensor == "magnetometer")
    omega, dt = inputs.sensors.omega_meas_radps, inputs.recording.dt
    monkeypatch.setattr(delay, "_KEPT", delay.OrderedDict())
    monkeypatch.setattr(delay, "KEPT_BYTES", field.body.nbytes + 1)   # room for one
    _, first = delay.timed_readings(omega, field.body, field.available, dt)
    _, second = delay.timed_readings(omega, np.roll(field.body, 3, axis=0), field.available, dt)
    assert len(delay._KEPT) == 1 and next(iter(delay._KEPT.values()))[1] is second
    with pytest.raises(ValueError, match="read-only"):     # shared by every caller
        second[0, 0] = 0.0
    # a field on time keeps only its fit, no readings: the caller keeps its own
    fit, on_time = delay.timed_readings(omega, first, field.available, dt)
    assert on_time is None and abs(fit.delay_s) < 0.5 * dt
    assert [kept is not None for _, kept in delay._KEPT.values()] == [True, False]
    # and a fit alone is kept as long as the count allows, none past it
    monkeypatch.setattr(delay, "KEPT_FITS", 1)
    delay.timed_readings(omega, np.roll(field.body, 1, axis=0), field.available, dt)
    assert len(delay._KEPT) == 1


@pytest.mark.slow
def test_a_trial_is_fitted_once_for_its_note_and_its_offline_estimators(monkeypatch, tmp_path):
    # broad's delay note and the offline estimators' timing read the same
    # readings: the second takes the first's fit (the warm-up's few samples
    # aside, too few to fit)
    from sensors import delay
    monkeypatch.setattr(delay, "_KEPT", delay.OrderedDict())
    lengths = []
    fitted = delay.delay_fit
    monkeypatch.setattr(delay, "delay_fit", lambda rates, *rest: (
        lengths.append(len(rates)), fitted(rates, *rest))[1])
    assert main(["broad", "--trials", "07", "--estimators", "mekf-smoother,vqf-offline",
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert sum(n > 1000 for n in lengths) == 1


def test_broad_says_which_estimators_timed_their_field(tmp_path, capsys):
    assert main(["broad", "--trials", "07", "--estimators", "mekf,vqf-offline", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert ("vqf-offline: the magnetometer taken at its samples' times, its delay against the "
            "gyro fitted per trial (12.8 ms, late where positive") in printed
    assert "mekf, " not in printed and "mekf:" not in printed


def test_the_fits_kept_stay_whole_under_threads(monkeypatch):
    # A worker may run tasks in threads: the kept fits' bookkeeping is
    # locked (without the lock, iterating them while another thread drops
    # one raised "OrderedDict mutated during iteration" here)
    import sys
    import threading
    from sensors import delay
    monkeypatch.setattr(delay, "_KEPT", delay.OrderedDict())
    monkeypatch.setattr(delay, "KEPT_FITS", 3)
    interval = sys.getswitchinterval()
    errors = []

    def fit_many(seed):
        rng = np.random.default_rng(seed)
        try:
            for _ in range(300):      # too few readings to fit: each call is quick
                delay.timed_readings(rng.normal(size=(8, 3)), rng.normal(size=(8, 3)),
                                     np.ones(8, dtype=bool), 0.01)
        except Exception as err:      # noqa: BLE001 - any error fails the test below
            errors.append(err)

    sys.setswitchinterval(1e-6)
    try:
        threads = [threading.Thread(target=fit_many, args=(seed,)) for seed in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    finally:
        sys.setswitchinterval(interval)
    assert errors == [] and len(delay._KEPT) <= 3
