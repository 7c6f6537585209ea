"""``attitude-bench inspect``: what a logged file holds, and the [recording]
declaration it suggests, which then runs as written (issue 30)."""
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.cli import main
from sensors.declared import UNITS, load_declared
from benchmarks.experiments.inspection import clipped, fitting_unit, rest_periods, time_unit
from sensors.recording import load_recording

TRIAL = Path(__file__).resolve().parents[1] / "datasets" / "broad" / \
    "02_undisturbed_slow_rotation_B.npz"


@pytest.fixture(scope="module")
def phone_csv(tmp_path_factory):
    """A shipped trial's first 60 s as a phone logs it: time in ms with
    jitter, the gyro in deg/s, the accelerometer in g, the magnetometer at a
    quarter of the rate in nT, the reference every second sample as x, y, z, w."""
    recording = load_recording(TRIAL)
    keep = int(60 * recording.rate_hz)
    rng = np.random.default_rng(3)
    frame = pd.DataFrame({"timestamp_ms": (recording.time_s[:keep] + rng.uniform(
        -0.2, 0.2, keep) / recording.rate_hz) * 1e3})
    for i, axis in enumerate("xyz"):
        frame[f"gyro_{axis}"] = np.degrees(recording.gyro_radps[:keep, i])
        frame[f"acc_{axis}"] = recording.accelerometer_mps2[:keep, i] / 9.80665
        field = np.full(keep, np.nan)
        field[::4] = recording.magnetometer_uT[:keep:4, i] * 1e3
        frame[f"mag_{axis}"] = field
    for axis in "xyzw":
        part = recording.reference_quat[:keep, "wxyz".index(axis)].copy()
        part[1::2] = np.nan
        frame[f"quat_{axis}"] = part
    folder = tmp_path_factory.mktemp("phone")
    frame.to_csv(folder / "phone.csv", index=False, float_format="%.17g")
    return folder / "phone.csv", recording


def test_inspect_reports_the_clocks_and_suggests_a_declaration_that_runs(phone_csv, capsys):
    path, recording = phone_csv
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    rates = {line.split()[0]: float(line.split("readings,")[1].split("Hz")[0])
             for line in out.splitlines() if "readings," in line}
    assert rates["gyro"] == pytest.approx(recording.rate_hz, rel=0.01)
    assert rates["magnetometer"] == pytest.approx(recording.rate_hz / 4, rel=0.01)
    assert "rest: " in out and "(first 0.0 to" in out     # BROAD's trials begin at rest
    # 40 s of rest and 20 s of a slow turn: too few of the field's directions
    # for the magnetometer's calibration, and inspect says so.
    assert "calibration: no ellipsoid fit" in out and "at least 70% of the directions" in out
    # The reference checked against the gyro (sensors.turning): BROAD's is
    # the IMU's own attitude, in its axes.
    import re
    found = re.search(r"reference: turns as the gyro does, ([0-9.]+) % of its turning "
                      r"unexplained; its axes ([0-9.]+)° from the gyro's", out)
    assert found and float(found[1]) < 2.0 and float(found[2]) < 2.0, out
    declared = path.with_suffix(".toml")
    text = declared.read_text()
    for expected in ('time_unit = "ms"', 'unit = "deg/s"', 'unit = "g"', 'unit = "nT"',
                     'columns = ["quat_w", "quat_x", "quat_y", "quat_z"]', 'order = "wxyz"'):
        assert expected in text, expected
    suggested = load_declared(declared)
    assert np.allclose(suggested.gyro_radps, recording.gyro_radps[:len(suggested.gyro_radps)],
                       rtol=1e-12, atol=1e-15)
    seen = ~np.isnan(suggested.reference_quat).any(axis=1)
    assert seen.mean() > 0.9                      # every second sample interpolated
    out_folder = path.parent / "scored"
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out",
                 str(out_folder), "--quiet"]) == 0
    assert (out_folder / "broad_trials.csv").exists()


@pytest.mark.parametrize("order", ["wxyz", "xyzw"])
def test_arrays_named_with_units_and_a_reference_in_either_order_are_told(order, tmp_path,
                                                                          capsys):
    """A logger's archive of (N, 3) arrays named with their units
    (``acc_m_s2``: its ``m`` is no magnetometer) and the reference as one
    (N, 4) array, whose order no name tells: its turning against the
    gyro's tells it (sensors.turning), and the note says so."""
    recording = load_recording(TRIAL)
    keep = int(120 * recording.rate_hz)          # the rest and a turn
    quat = recording.reference_quat[:keep]
    np.savez(tmp_path / "log.npz", t_s=recording.time_s[:keep],
             gyro_rad_s=recording.gyro_radps[:keep], acc_m_s2=recording.accelerometer_mps2[:keep],
             mag_uT=recording.magnetometer_uT[:keep],
             q_mocap=quat if order == "wxyz" else np.roll(quat, -1, axis=1))
    assert main(["inspect", str(tmp_path / "log.npz")]) == 0
    err = capsys.readouterr().err
    assert f"is told by its turning against the gyro's: {order}" in err, err
    text = (tmp_path / "log.toml").read_text()
    assert 'columns = "acc_m_s2"' in text and f'order = "{order}"' in text
    told = load_declared(tmp_path / "log.toml").reference_quat
    seen = ~np.isnan(quat).any(axis=1)
    assert np.allclose(np.abs(np.sum(told[seen] * quat[seen], axis=1)), 1.0)


def test_inspect_never_overwrites_a_declaration(phone_csv, capsys, tmp_path):
    path, _ = phone_csv
    (tmp_path / "phone.toml").write_text("# mine\n")
    assert main(["inspect", str(path), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already holds phone.toml" in err
    assert (tmp_path / "phone.toml").read_text() == "# mine\n"


def test_inspect_says_what_it_cannot_tell(tmp_path, capsys):
    pd.DataFrame({"when": np.arange(10.0), "u": np.ones(10)}).to_csv(tmp_path / "odd.csv",
                                                                     index=False)
    assert main(["inspect", str(tmp_path / "odd.csv")]) == 2
    err = capsys.readouterr().err
    assert "no columns recognised as gyro" in err and "no time column recognised" in err
    assert "does not load" in err


@settings(max_examples=40, deadline=None)
@given(st.floats(22.0, 67.0), st.sampled_from(sorted(UNITS["magnetometer"])),
       st.integers(0, 2**32 - 1))
def test_the_unit_that_puts_an_earth_field_in_place_is_found(norm_uT, unit, seed):
    # Any field of the Earth's size (22 to 67 µT), in any direction, written
    # in any of the units: the unit is recovered (they differ by 10 or more).
    directions = np.random.default_rng(seed).standard_normal((50, 3))
    field = norm_uT * directions / np.linalg.norm(directions, axis=1)[:, None]
    assert fitting_unit("magnetometer", field / UNITS["magnetometer"][unit]) == unit


def test_time_units_clipping_and_rest_on_made_data():
    assert time_unit(np.full(5, 5.0)) == "ms" and time_unit(np.full(5, 0.005)) == "s"
    assert time_unit(np.full(5, 5e6)) == "ns"
    # 1 kHz in ms and in µs, 2 kHz in ns, 10 Hz in s: each unit a thousand apart
    assert [time_unit(np.full(5, v)) for v in (1.0, 1000.0, 5e5, 0.1)] == ["ms", "us", "ns", "s"]
    rail = np.zeros((100, 3))
    rail[10:15, 0] = 34.9
    assert clipped(rail) == (5, 34.9)
    assert clipped(rail[:12]) == (0, 34.9)          # two at the extreme: no rail
    quantised = np.zeros((100, 3))
    quantised[10:20:2, 0] = 43.0                    # the extreme now and then, never on end
    assert clipped(quantised) == (0, 43.0)
    dt = 0.01
    rates = np.zeros((1000, 3))
    rates[400:, 2] = 1.0                              # turning from 4 s on
    force = np.tile([0.0, 0.0, 9.81], (1000, 1))
    periods = rest_periods(rates, force, dt)
    assert len(periods) == 1 and periods[0][0] == 0.0 and 3.5 <= periods[0][1] <= 4.0
    assert rest_periods(rates[400:], force[400:], dt) == []
    assert fitting_unit("accelerometer", force / 9.80665) == "g"
    assert fitting_unit("accelerometer", force) == "m/s^2"


def _readme_phone(path: Path, seconds: float = 30.0) -> Path:
    """The README's phone: ``t_ms``, ``gx``…, and the magnetometer on its
    own clock ``t_mag_ms`` beside ``mx``… (a quarter of the rate; empty
    cells between its readings), no reference."""
    recording = load_recording(TRIAL)
    keep = int(seconds * recording.rate_hz)
    frame = pd.DataFrame({"t_ms": recording.time_s[:keep] * 1e3})
    for i, axis in enumerate("xyz"):
        frame[f"g{axis}"] = recording.gyro_radps[:keep, i]
        frame[f"a{axis}"] = recording.accelerometer_mps2[:keep, i]
    frame["t_mag_ms"] = np.where(np.arange(keep) % 4 == 0, frame["t_ms"] + 0.5, np.nan)
    for i, axis in enumerate("xyz"):
        frame[f"m{axis}"] = np.where(np.arange(keep) % 4 == 0,
                                     recording.magnetometer_uT[:keep, i], np.nan)
    frame.to_csv(path, index=False, float_format="%.17g")
    return path


def test_the_readme_phones_magnetometer_keeps_its_own_clock(tmp_path, capsys):
    path = _readme_phone(tmp_path / "phone.csv")
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    magnetometer = [line for line in out.splitlines() if line.split()[:1] == ["magnetometer"]]
    rate = float(magnetometer[0].split("readings,")[1].split("Hz")[0])
    assert rate == pytest.approx(load_recording(TRIAL).rate_hz / 4, rel=0.01)
    text = path.with_suffix(".toml").read_text()
    assert '[recording.magnetometer]\ntime = "t_mag_ms"' in text, text


def test_inspect_reads_matlab_vectors_and_a_commented_csv(tmp_path, capsys):
    from scipy.io import savemat
    csv = _readme_phone(tmp_path / "phone.csv", seconds=10.0)
    frame = pd.read_csv(csv)
    savemat(tmp_path / "phone_mat.mat", {name: frame[name].to_numpy() for name in frame})
    commented = tmp_path / "phone_commented.csv"
    commented.write_text("# logger v2.1\n# 286 Hz\n" + csv.read_text())
    for path in (tmp_path / "phone_mat.mat", commented):
        assert main(["inspect", str(path)]) == 0, path
        out = capsys.readouterr().out
        assert "gyro" in out and "readings," in out and path.with_suffix(".toml").exists()


def test_a_parquet_file_without_its_engine_names_the_package(tmp_path, monkeypatch):
    import pandas
    from dynamics.validation import InvalidParameterError
    from sensors.tables import read_table

    def no_engine(*args, **kwargs):
        raise ImportError("Unable to find a usable engine; tried using: 'pyarrow'")
    monkeypatch.setattr(pandas, "read_parquet", no_engine)
    (tmp_path / "log.parquet").write_bytes(b"PAR1")
    with pytest.raises(InvalidParameterError, match="needs pyarrow, which is not installed"):
        read_table(tmp_path / "log.parquet")


def test_replay_of_a_declaration_without_a_reference_says_so(tmp_path, capsys):
    path = _readme_phone(tmp_path / "phone.csv", seconds=10.0)
    assert main(["inspect", str(path)]) == 0
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["replay", "--dataset", str(path.with_suffix(".toml")), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "declares no reference attitude ([recording.reference])" in err
    assert err.count("\n") == 1 and not out.exists()


def test_a_clocks_jitter_is_its_spread_between_its_gaps():
    """A 200 Hz clock with one 2 s gap: jitter 0 and one gap (the gap's
    interval counted in the jitter made it 371 %); jittered by ±0.2 of a
    step (uniform), its spread is 0.4/√12·√2 ≈ 16 % of the step."""
    from benchmarks.experiments.inspection import clock
    times = np.concatenate([np.arange(2000) * 0.005, 12.0 + np.arange(2000) * 0.005])
    found = clock(times)
    assert found["gaps"] == 1 and found["jitter"] < 1e-9
    assert found["interval"] == pytest.approx(0.005, rel=1e-9)
    jittered = times + np.random.default_rng(0).uniform(-0.2, 0.2, len(times)) * 0.005
    assert clock(jittered)["jitter"] == pytest.approx(0.4 / np.sqrt(12) * np.sqrt(2), rel=0.1)


def test_a_quaternion_in_numbered_columns_is_the_reference():
    """q0…q3 (q0 the scalar, as in Madgwick's code) is the reference in the
    order w, x, y, z, whatever the file's order."""
    from benchmarks.experiments.columns import sensor_columns
    table = {name: np.zeros(10) for name in ("t", "gx", "gy", "gz", "q3", "q1", "q0", "q2")}
    assert sensor_columns(table)["reference"] == ["q0", "q1", "q2", "q3"]
    table = {name: np.zeros(10) for name in ("t", "quat_1", "quat_2", "quat_3", "quat_0")}
    assert sensor_columns(table)["reference"] == ["quat_0", "quat_1", "quat_2", "quat_3"]


def test_a_reference_that_does_not_turn_with_the_gyro_is_not_said_to():
    """A reference held still while the gyro turns: inspect's line says it
    does not turn as the gyro does (it said it did, at 92 % unexplained)."""
    from dataclasses import replace
    from benchmarks.experiments.inspection import _reference_turning
    recording = load_recording(TRIAL)
    held = replace(recording, reference_quat=np.tile([1.0, 0.0, 0.0, 0.0],
                                                      (recording.n_samples, 1)))
    assert _reference_turning(held).startswith("reference: does not turn as the gyro does")
    assert _reference_turning(recording).startswith("reference: turns as the gyro does")


@pytest.mark.parametrize("columns, runs", [
    (["timestamp_ms", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"],
     "then run: attitude-bench broad --broad"),
    (["timestamp_ms", "gyro_x", "gyro_y", "gyro_z", "quat_x", "quat_y", "quat_z", "quat_w"],
     "then run: attitude-bench replay --dataset"),
    (["timestamp_ms", "gyro_x", "gyro_y", "gyro_z"], "a gyro alone runs with nothing here")])
def test_inspect_names_the_command_that_runs_what_the_file_holds(phone_csv, tmp_path, capsys,
                                                                 columns, runs):
    # broad needs an accelerometer and replay a reference: a gyro and a
    # reference were told to run broad, which refused them.
    pd.read_csv(phone_csv[0])[columns].to_csv(tmp_path / "log.csv", index=False)
    assert main(["inspect", str(tmp_path / "log.csv")]) == 0
    assert runs in capsys.readouterr().out
    assert runs.replace("then run: ", "") in (tmp_path / "log.toml").read_text()


def test_inspect_times_the_magnetometer_against_the_gyro(tmp_path, capsys):
    """BROAD's magnetometer reads about 13 ms late against its gyro
    (sensors.delay); a minute of the fast trial is enough to say so, and
    the same readings put at their times are said to be on time."""
    from sensors.delay import at_sample_times, delay_fit
    recording = load_recording(TRIAL.with_name("07_undisturbed_fast_rotation_B.npz"))
    keep = int(60 * recording.rate_hz)
    gyro, field = recording.gyro_radps[:keep], recording.magnetometer_uT[:keep]
    read = np.ones(keep, dtype=bool)
    fit = delay_fit(gyro, field, read, recording.dt)
    for name, mag in (("late", field),
                      ("timed", at_sample_times(gyro, field, read, recording.dt, fit.delay_s,
                                                fit.offset))):
        np.savez(tmp_path / f"{name}.npz", t_s=recording.time_s[:keep], gyro_rad_s=gyro,
                 acc_m_s2=recording.accelerometer_mps2[:keep], mag_uT=mag)
        assert main(["inspect", str(tmp_path / f"{name}.npz")]) == 0
        out = capsys.readouterr().out
        line = next(line for line in out.splitlines() if "magnetometer timing" in line)
        if name == "late":
            assert "reads 13.0 ± 0.2 ms late against the gyro" in line, line
            assert "--magnetometer-delay auto" in line
        else:
            assert "on time as far as its turning tells" in line, line


def test_inspect_counts_rows_of_zeros_as_no_reading(phone_csv, tmp_path, capsys):
    # The magnetometer logs zeros for its second half (a logger that writes
    # a row even where the sensor gave nothing): as the loader, inspect
    # counts only its readings (it had counted the zeros too).
    path, _ = phone_csv
    frame = pd.read_csv(path)
    mag, second = ["mag_x", "mag_y", "mag_z"], frame.index >= len(frame) // 2
    frame.loc[second, mag] = frame.loc[second, mag] * 0.0     # its readings zero, NaN kept
    frame.to_csv(tmp_path / "zeros.csv", index=False, float_format="%.17g")
    assert main(["inspect", str(tmp_path / "zeros.csv"), "--out", str(tmp_path / "o")]) == 0
    counts = {line.split()[0]: int(line.split()[1].replace(",", ""))
              for line in capsys.readouterr().out.splitlines() if "readings," in line}
    assert counts["magnetometer"] == np.count_nonzero(frame.loc[~second, "mag_x"].notna())
    assert counts["gyro"] == len(frame)


def test_inspect_refuses_a_read_only_folder_beside_the_file_before_any_work(phone_csv, tmp_path,
                                                                           capsys, monkeypatch):
    # Without --out the declaration goes beside the file: a folder that
    # cannot take it is refused first, naming --out (the report had been
    # printed, then a temporary file's name given as the error). The folder
    # is read-only as the system says (os.access), whoever runs the test.
    path, _ = phone_csv
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "phone.csv").write_bytes(path.read_bytes())
    access = os.access
    monkeypatch.setattr(os, "access", lambda where, mode: Path(where) != folder
                        and access(where, mode))
    assert main(["inspect", str(folder / "phone.csv")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "is not writable" in captured.err and "give --out DIR" in captured.err
    assert not (folder / "phone.toml").exists()


def test_inspect_guesses_past_an_infinite_reading_and_names_its_row(phone_csv, tmp_path, capsys):
    # One infinite gyro reading: the guess reads it as no reading (it had
    # passed numpy's overflow warnings on as three notes, and guessed the
    # units from a rate of 1.8e308), and the declaration's check names the row
    path, _ = phone_csv
    frame = pd.read_csv(path)
    frame.loc[2000, "gyro_y"] = np.inf
    frame.to_csv(tmp_path / "inf.csv", index=False, float_format="%.17g")
    assert main(["inspect", str(tmp_path / "inf.csv"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "encountered" not in err
    assert "row 2000 holds an infinite value" in err
    assert 'unit = "deg/s"' in (tmp_path / "o" / "inf.toml").read_text()


def test_times_printed_coarser_than_the_clock_are_still_the_time_column(phone_csv, tmp_path,
                                                                         capsys):
    # A logger printing its time in steps of two samples (each time twice, as
    # an Arduino's Serial.print(t, 2) at 200 Hz): the loader spreads each run
    # of equal times (sensors.clocks.dequantized), and inspect now reads the
    # column as the loader does. It had found no time column at all.
    path, recording = phone_csv
    frame = pd.read_csv(path)
    frame["timestamp_ms"] = (np.arange(len(frame)) // 2) * 2e3 / recording.rate_hz
    frame.to_csv(tmp_path / "coarse.csv", index=False, float_format="%.17g")
    assert main(["inspect", str(tmp_path / "coarse.csv"), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert "no time column recognised" not in err
    rates = {line.split()[0]: float(line.split("readings,")[1].split("Hz")[0])
             for line in out.splitlines() if "readings," in line}
    assert rates["gyro"] == pytest.approx(recording.rate_hz, rel=0.02)
    suggested = load_declared(tmp_path / "o" / "coarse.toml")
    assert len(suggested.gyro_radps) == len(frame)


def test_an_uneven_loop_printed_coarsely_is_told_at_the_rate_the_loader_reads(phone_csv,
                                                                              tmp_path, capsys):
    # A loop whose intervals vary by ±80 % of its period, its time printed
    # to 10 ms: the spread times keep no steady clock, and the loader
    # resamples the gyro at their mean interval. inspect told the fitted
    # line's rate instead, which counts uneven intervals as dropped samples
    # (291 Hz here, where the loader reads 285 Hz; 361 Hz, with 369 "gaps",
    # for a longer log); now it tells the loader's rate.
    path, recording = phone_csv
    frame = pd.read_csv(path)
    period = 1e3 / recording.rate_hz
    times = np.cumsum(period * (1.0 + np.random.default_rng(5).uniform(-0.8, 0.8, len(frame))))
    frame["timestamp_ms"] = np.floor(times / 10.0) * 10.0
    frame.to_csv(tmp_path / "loop.csv", index=False, float_format="%.17g")
    assert main(["inspect", str(tmp_path / "loop.csv"), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    gyro = next(line for line in out.splitlines() if line.split()[:1] == ["gyro"])
    told = float(gyro.split("readings,")[1].split("Hz")[0])
    with pytest.warns(UserWarning, match="keep no steady clock"):
        loaded = load_declared(tmp_path / "o" / "loop.toml")
    assert told == pytest.approx(loaded.rate_hz, rel=1e-3), gyro
    assert gyro.endswith(" 0 gaps"), gyro


def test_a_held_time_is_the_time_column_only_where_no_other_increases():
    # A 1 Hz GPS time held over a 200 Hz log's rows repeats, and spread it
    # would increase: the column that increases as printed comes first; and
    # a file without a header takes no steadily rising integer (a
    # temperature) for its time.
    from benchmarks.experiments.columns import columns_by_values, time_columns
    n = 2000
    table = {"gps_time": np.floor(np.arange(n) / 200.0), "t": np.arange(n) * 5e-3}
    assert time_columns(table) == ["t", "gps_time"]
    assert time_columns({"gps_time": table["gps_time"]}) == ["gps_time"]
    rng = np.random.default_rng(0)
    headerless = {"1": np.floor(np.linspace(20.0, 30.0, n))}
    for i, column in enumerate(rng.normal(0.0, 1.0, (6, n)), start=2):
        headerless[str(i)] = column
    assert columns_by_values(headerless)[1] == []
