"""A logger's file as its logger writes it (sensors/tables.py,
sensors/clocks.py, sensors/declared_units.py): any separator, decimal
commas, a preamble of '#' or '//' lines, a trailing separator, no header;
a counter's roll-over; times in a tick of the logger's own; and a gyro or a
clock in the wrong unit named, with the one that fits, where only the
reference shows it."""
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.cli import main
from dynamics.validation import InvalidParameterError
from sensors.clocks import COUNTER_MODULI, unwrapped
from sensors.declared import load_declared
from sensors.recording import load_recording
from sensors.tables import csv_layout, read_table

TRIAL = Path(__file__).resolve().parents[1] / "datasets" / "broad" / \
    "02_undisturbed_slow_rotation_B.npz"
#: Of the trial: its rest (40 s) and 40 s of its movement.
SECONDS = 80.0


@pytest.fixture(scope="module")
def trial():
    recording = load_recording(TRIAL)
    return recording, int(SECONDS * recording.rate_hz)


# -- reading the file ---------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(st.sampled_from([",", ";", "\t", "|", " "]), st.booleans(), st.booleans(),
       st.booleans(), st.sampled_from(["", "#", "//"]), st.integers(0, 2**32 - 1))
def test_any_layout_of_the_same_numbers_reads_the_same_columns(
        tmp_path_factory, separator, decimal_comma, header, trailing, preamble, seed):
    # The same numbers written with any separator, a decimal comma where
    # the separator is not one, with or without a header, a trailing
    # separator and a preamble, read back as the same columns, exactly
    # (repr of a float reads back as its bits).
    decimal_comma = decimal_comma and separator != ","
    values = np.random.default_rng(seed).normal(size=(6, 4)) * 10.0 ** np.arange(-3, 1)
    values[:, 0] = np.arange(6) * 0.005 + 1.25
    names = ["t", "gyro_x", "gyro_y", "gyro_z"]

    def text(x: float) -> str:
        return repr(x).replace(".", ",") if decimal_comma else repr(x)
    lines = [f"{preamble} device: a logger, 200 Hz"] * 3 if preamble else []
    lines += [separator.join(names)] if header else []
    lines += [separator.join(map(text, row)) + (separator if trailing else "")
              for row in values.tolist()]
    path = tmp_path_factory.mktemp("layout") / "log.csv"
    path.write_text("\n".join(lines) + "\n")
    table = read_table(path)
    expected = names if header else ["1", "2", "3", "4"]
    assert list(table) == expected
    for column, name in enumerate(expected):
        assert np.array_equal(table[name], values[:, column]), (name, csv_layout(path))


def test_a_header_with_quoted_separators_keeps_its_columns(tmp_path):
    # phyphox quotes its headers; a quoted comma is no separator
    path = tmp_path / "log.csv"
    path.write_text('"Time (s)","Acceleration (m/s^2, x)","y","z"\n0.0,1.0,2.0,9.8\n'
                    '0.01,1.5,2.5,9.7\n')
    assert list(read_table(path)) == ["Time (s)", "Acceleration (m/s^2, x)", "y", "z"]


# -- a counter that rolls over ----------------------------------------------

@settings(max_examples=100, deadline=None)
@given(st.sampled_from(COUNTER_MODULI), st.integers(1, 20_000), st.integers(3, 300),
       st.integers(0, 299))
def test_a_counter_that_rolls_over_is_unwrapped(modulus, step, count, before_roll):
    # Times of a counter (micros(), a 16-bit tick) read modulo its size
    # are the times themselves once unwrapped, wherever the roll-over falls.
    step = min(step, (modulus - 1) // count)       # the log spans less than one roll-over
    start = modulus - min(before_roll, count - 1) * step - 1
    times = start + step * np.arange(count, dtype=np.int64)
    assert np.array_equal(unwrapped(times % modulus), times)
    assert np.array_equal(unwrapped(times - start), times - start)     # no roll-over: as it is


def test_times_that_go_back_otherwise_are_left_for_the_check_to_name():
    times = np.array([1000, 2000, 3000, 1500, 2500], dtype=np.int64)
    assert np.array_equal(unwrapped(times), times)                     # back by 1500: no counter
    floats = np.array([4294967000.0, 4294967200.0, 104.0])
    assert np.array_equal(unwrapped(floats), floats)                   # only integer counters


DECLARATION = """[recording]
file = "log.csv"
time_unit = {time_unit}

[recording.gyro]
time = "t"
columns = ["gx", "gy", "gz"]
unit = "{gyro_unit}"
{accelerometer}
[recording.reference]
time = "t"
columns = ["qw", "qx", "qy", "qz"]
"""
ACCELEROMETER = """
[recording.accelerometer]
time = "t"
columns = ["ax", "ay", "az"]
unit = "m/s^2"
"""
MAGNETOMETER = """
[recording.magnetometer]
time = "t"
columns = ["mx", "my", "mz"]
unit = "uT"
"""


def _log(trial, folder: Path, ticks: np.ndarray, time_unit: str, gyro_scale: float = 1.0,
         accelerometer: bool = True) -> Path:
    """The trial's first SECONDS with the integer ``ticks`` as its times."""
    recording, keep = trial
    columns = {"t": ticks[:keep]}
    for prefix, channel, scale in (("g", recording.gyro_radps, gyro_scale),
                                   ("a", recording.accelerometer_mps2, 1.0),
                                   ("m", recording.magnetometer_uT, 1.0)):
        columns.update({f"{prefix}{axis}": channel[:keep, i] * scale
                        for i, axis in enumerate("xyz")})
    columns.update({f"q{part}": recording.reference_quat[:keep, i]
                    for i, part in enumerate("wxyz")})
    rows = zip(*([str(int(x)) for x in columns["t"]],
                 *([repr(x) for x in values.tolist()] for name, values in columns.items()
                   if name != "t")))
    (folder / "log.csv").write_text(",".join(columns) + "\n"
                                    + "\n".join(map(",".join, rows)) + "\n")
    path = folder / "log.toml"
    path.write_text(DECLARATION.format(time_unit=time_unit, gyro_unit="rad/s" if gyro_scale == 1
                                       else "deg/s", accelerometer=ACCELEROMETER
                                       if accelerometer else ""))
    return path


def test_a_micros_clock_that_rolls_over_loads_as_the_unwrapped_one(trial, tmp_path):
    # An Arduino's micros() passing 2**32 in the middle of the log: the same
    # recording as the times that never roll over.
    recording, keep = trial
    micros = np.rint(recording.time_s * 1e6).astype(np.int64) + 2**32 - 20_000_000
    wrapped = load_declared(_log(trial, tmp_path, micros % 2**32, '"us"'))
    (tmp_path / "whole").mkdir()
    whole = load_declared(_log(trial, tmp_path / "whole", micros - 2**32 + 40_000_000, '"us"'))
    assert wrapped.rate_hz == pytest.approx(whole.rate_hz, rel=1e-12)
    assert np.array_equal(wrapped.gyro_radps, whole.gyro_radps)
    assert np.allclose(wrapped.reference_quat, whole.reference_quat, atol=1e-12, equal_nan=True)


def test_a_tick_of_its_own_is_declared_as_a_number(trial, tmp_path):
    # Xsens's SampleTimeFine counts 100 µs: time_unit = 1e-4 reads it as
    # the seconds it is, the rate the trial's own.
    recording, _ = trial
    ticks = np.rint(recording.time_s * 1e4).astype(np.int64) + 123_456
    declared = load_declared(_log(trial, tmp_path, ticks, "1e-4"))
    assert declared.rate_hz == pytest.approx(recording.rate_hz, rel=1e-3)
    with pytest.raises(InvalidParameterError, match=r"time_unit = -1.*a positive number"):
        load_declared(_log(trial, tmp_path, ticks, "-1"))


@pytest.mark.parametrize("time_unit, hint", [('"ms"', "0.1 ms"), ('"us"', "100 µs")])
def test_a_clock_in_the_wrong_tick_is_named_with_the_tick_that_fits(trial, tmp_path,
                                                                     time_unit, hint):
    # Ticks of 100 µs declared in ms (everything 10 times too slow) or in µs
    # (100 times too fast: the usual 0.1 s window then holds 10 s of the
    # turning, which averages out; the shorter windows see it): the clock's
    # unit is named, with 1e-4, where the gyro's was blamed before.
    recording, _ = trial
    ticks = np.rint(recording.time_s * 1e4).astype(np.int64)
    with pytest.raises(InvalidParameterError) as refused:
        load_declared(_log(trial, tmp_path, ticks, time_unit))
    message = str(refused.value)
    assert f"recording.time_unit = {time_unit.strip(chr(34))!r}" in message, message
    assert "time_unit = 0.0001" in message, (hint, message)


def test_a_gyro_in_the_wrong_unit_is_named_where_only_the_reference_shows_it(trial, tmp_path):
    # rad/s declared deg/s, no accelerometer (a gyro and a reference, as
    # replay takes): the gyro turns 57 times too slowly to show any
    # turning of its own, and the reference turns at the gyro's real rate.
    recording, _ = trial
    ticks = np.rint(recording.time_s * 1e6).astype(np.int64)
    path = _log(trial, tmp_path, ticks, '"us"', gyro_scale=1.0, accelerometer=False)
    path.write_text(path.read_text().replace('unit = "rad/s"', 'unit = "deg/s"'))
    with pytest.raises(InvalidParameterError, match=r"recording\.gyro\.unit = 'deg/s': makes "
                       r"the gyro turn 5\d(\.\d)? times slower than the reference turns "
                       r"\(were they rad/s\? unit = \"rad/s\"\)"):
        load_declared(path)
    path.write_text(path.read_text().replace('unit = "deg/s"', 'unit = "rad/s"'))
    assert load_declared(path).rate_hz == pytest.approx(recording.rate_hz, rel=1e-9)


def test_euler_angles_in_the_wrong_unit_name_the_unit(trial, tmp_path):
    # The reference as ZYX Euler angles in radians, declared in degrees:
    # the refusal names recording.reference.unit (it named sequence).
    from scipy.spatial.transform import Rotation
    recording, _ = trial
    ticks = np.rint(recording.time_s * 1e6).astype(np.int64)
    path = _log(trial, tmp_path, ticks, '"us"')
    text = (tmp_path / "log.csv").read_text().splitlines()
    header, rows = text[0].split(","), [line.split(",") for line in text[1:]]
    quat = np.array([[float(row[header.index(f"q{part}")]) for part in "wxyz"] for row in rows])
    euler = np.full((len(quat), 3), np.nan)        # none during the rest
    seen = ~np.isnan(quat).any(axis=1)
    euler[seen] = Rotation.from_quat(quat[seen], scalar_first=True).as_euler("ZYX")
    lines = [",".join(header[:-4] + ["yaw", "pitch", "roll"])]
    lines += [",".join(row[:-4] + ["" if math.isnan(x) else repr(x) for x in angles])
              for row, angles in zip(rows, euler.tolist())]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    path.write_text(path.read_text().replace('columns = ["qw", "qx", "qy", "qz"]',
                                             'columns = ["yaw", "pitch", "roll"]\n'
                                             'sequence = "ZYX"\nunit = "deg"'))
    with pytest.raises(InvalidParameterError, match=r"recording\.reference\.unit = 'deg'.*"
                       r"unit = \"rad\" would fit"):
        load_declared(path)
    path.write_text(path.read_text().replace('unit = "deg"\n', 'unit = "rad"\n'))
    assert math.isfinite(load_declared(path).rate_hz)


# -- inspect ----------------------------------------------------------------

def test_inspect_reads_a_ros_export_and_a_tick_of_its_own(trial, tmp_path, capsys):
    # rostopic echo -p's names (field.angular_velocity.x …, the
    # orientation's covariances beside it) and Xsens's SampleTimeFine in
    # 100 µs ticks, camelCase: the suggestion loads, the orientation is the
    # reference, its tick is 1e-4.
    recording, keep = trial
    ticks = np.rint(recording.time_s[:keep] * 1e4).astype(np.int64) + 5_000
    columns = {"SampleTimeFine": [str(int(x)) for x in ticks]}
    for ros, channel in (("angular_velocity", recording.gyro_radps),
                         ("linear_acceleration", recording.accelerometer_mps2)):
        columns.update({f"field.{ros}.{axis}": [repr(x) for x in channel[:keep, i].tolist()]
                        for i, axis in enumerate("xyz")})
    columns.update({f"field.orientation.{part}": [repr(x) for x in
                                                  recording.reference_quat[:keep, i].tolist()]
                    for i, part in enumerate("wxyz")})
    columns.update({f"field.orientation_covariance{i}": ["0.0"] * keep for i in range(4)})
    (tmp_path / "imu.csv").write_text(",".join(columns) + "\n" + "\n".join(
        map(",".join, zip(*columns.values()))) + "\n")
    assert main(["inspect", str(tmp_path / "imu.csv")]) == 0, capsys.readouterr().err
    text = (tmp_path / "imu.toml").read_text()
    assert "time_unit = 0.0001" in text
    assert 'columns = ["field.angular_velocity.x", "field.angular_velocity.y", ' \
           '"field.angular_velocity.z"]' in text
    assert '"field.orientation.w", "field.orientation.x"' in text and "covariance" not in text
    assert "magnetometer" not in text
    assert load_declared(tmp_path / "imu.toml").rate_hz == pytest.approx(recording.rate_hz,
                                                                         rel=1e-3)


def test_a_folder_mixing_referenced_and_unreferenced_logs_says_which_has_none(
        trial, tmp_path, capsys):
    # One log with a reference and one without, in one folder: the one
    # without is left out of the means as having no reference (it was said
    # to "never move"), its rows scored by agreement with the others.
    recording, _ = trial
    ticks = np.rint(recording.time_s * 1e6).astype(np.int64)
    path = _log(trial, tmp_path, ticks, '"us"')
    text = path.read_text().replace("[recording.reference]", MAGNETOMETER + "[recording.reference]")
    path.rename(tmp_path / "with.toml")
    (tmp_path / "with.toml").write_text(text)
    (tmp_path / "without.toml").write_text(text[:text.index("[recording.reference]")])
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(tmp_path), "--estimators", "mekf,vqf,madgwick",
                 "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "left out of the means: without has no reference during its movement" in printed
    assert "never moves" not in printed
    import pandas as pd
    rows = pd.read_csv(out / "broad_trials.csv").set_index(["trial", "estimator"])
    assert np.isfinite(rows.loc[("with", "mekf"), "total_rmse_deg"])
    assert np.isnan(rows.loc[("without", "mekf"), "total_rmse_deg"])
    assert np.isfinite(rows.loc[("without", "mekf"), "agreement_total_deg"])


def test_inspect_tells_a_headerless_files_columns_by_their_values(trial, tmp_path, capsys):
    # No header (an Arduino sketch's ';'-separated log): the time is the
    # column that increases, a steady norm near g (in g here) the
    # accelerometer's, one near the Earth's field (in gauss: also about 1,
    # but 1 g is exactly g) the magnetometer's, the unsteady one the gyro's,
    # four of unit norm the reference; the suggestion loads.
    recording, keep = trial
    micros = np.rint(recording.time_s[:keep] * 1e6).astype(np.int64) + 1_000_000
    blocks = [recording.accelerometer_mps2[:keep] / 9.80665,
              np.degrees(recording.gyro_radps[:keep]),
              recording.magnetometer_uT[:keep] / 100.0, recording.reference_quat[:keep]]
    rows = [";".join([str(int(t))] + ["" if math.isnan(x) else repr(x) for x in row])
            for t, row in zip(micros, np.hstack(blocks).tolist())]
    (tmp_path / "LOG.csv").write_text("\n".join(rows) + "\n")
    assert main(["inspect", str(tmp_path / "LOG.csv")]) == 0, capsys.readouterr().err
    text = (tmp_path / "LOG.toml").read_text()
    for sensor, columns, unit in (("accelerometer", '["2", "3", "4"]', '"g"'),
                                  ("gyro", '["5", "6", "7"]', '"deg/s"'),
                                  ("magnetometer", '["8", "9", "10"]', '"gauss"')):
        section = text.split(f"[recording.{sensor}]")[1].split("[recording.")[0]
        assert f"columns = {columns}" in section and f"unit = {unit}" in section, text
    assert 'columns = ["11", "12", "13", "14"]' in text and 'time_unit = "us"' in text
    assert "no header: the columns are told by their values" in capsys.readouterr().err
    assert load_declared(tmp_path / "LOG.toml").rate_hz == pytest.approx(recording.rate_hz,
                                                                         rel=1e-3)
