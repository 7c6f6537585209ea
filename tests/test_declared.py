"""A logger's file declared by a [recording] TOML (issue 30): the same data
gives the same numbers whatever its format, sensors on their own clocks
and in their own units reach the scored table, and each mistake a logger
makes is one line."""
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from benchmarks.cli import main
from benchmarks.experiments.replay import open_dataset
from dynamics.validation import InvalidParameterError
from sensors.declared import load_declared, load_parts
from sensors.tables import read_table
from sensors.recording import load_recording

TRIAL = Path(__file__).resolve().parents[1] / "datasets" / "broad" / \
    "02_undisturbed_slow_rotation_B.npz"
SECONDS = 40.0          # of the trial: enough for a rest, the start and a movement


@pytest.fixture(scope="module")
def trial():
    recording = load_recording(TRIAL)
    keep = int(SECONDS * recording.rate_hz)
    return recording, keep


def _table(trial, whole: bool = False) -> dict:
    """The trial's first SECONDS (or all of it) as one table on the gyro's
    clock, SI units."""
    recording, keep = trial
    keep = recording.n_samples if whole else keep
    table = {"t": recording.time_s[:keep]}
    for prefix, channel in (("g", recording.gyro_radps), ("a", recording.accelerometer_mps2),
                            ("m", recording.magnetometer_uT)):
        table.update({f"{prefix}{axis}": channel[:keep, i] for i, axis in enumerate("xyz")})
    table.update({f"q{part}": recording.reference_quat[:keep, i]
                  for i, part in enumerate("wxyz")})
    return table


DECLARATION = """[recording]
file = "{file}"
time_unit = "{time_unit}"

[recording.gyro]
time = "t"
columns = ["gx", "gy", "gz"]
unit = "{gyro_unit}"

[recording.accelerometer]
time = "t"
columns = ["ax", "ay", "az"]
unit = "{acc_unit}"

[recording.magnetometer]
time = "{mag_time}"
columns = ["mx", "my", "mz"]
unit = "{mag_unit}"

[recording.reference]
time = "t"
columns = {reference}
{reference_keys}
"""


def _declare(folder: Path, file: str, **given) -> Path:
    keys = dict(time_unit="s", gyro_unit="rad/s", acc_unit="m/s^2", mag_unit="uT",
                mag_time="t", reference='["qw", "qx", "qy", "qz"]', reference_keys="")
    keys.update(given)
    path = folder / f"{Path(file).stem}.toml"
    path.write_text(DECLARATION.format(file=file, **keys))
    return path


def _csv(folder: Path, table: dict, name: str = "log.csv") -> str:
    """The table as a CSV file, each number's shortest exact text (a float
    reads back as the same bits), an empty field where it is NaN."""
    columns = [_fields(np.asarray(values, dtype=float)) for values in table.values()]
    rows = map(",".join, zip(*columns, strict=True))
    (folder / name).write_text(",".join(table) + "\n" + "\n".join(rows) + "\n")
    return name


_FIELDS: dict = {}


@pytest.fixture(scope="module", autouse=True)
def _forget_fields():
    """The columns' text is kept for this module's tests only."""
    yield
    _FIELDS.clear()


def _fields(values: np.ndarray) -> tuple:
    """A column of floats as CSV fields, kept by its bits: most tests here
    change a column or two of the same trial, and writing every number of a
    whole trial as text (pandas' ``to_csv``) took two seconds a test."""
    key = values.tobytes()
    if key not in _FIELDS:
        _FIELDS[key] = tuple("" if math.isnan(x) else repr(x) for x in values.tolist())
    return _FIELDS[key]


def test_the_same_data_in_any_format_is_the_same_recording(trial, tmp_path):
    recording, keep = trial
    table = _table(trial)
    files = {"log.csv": None, "log.npz": None, "log.mat": None, "log.h5": None}
    _csv(tmp_path, table)
    np.savez(tmp_path / "log.npz", **table)
    from scipy.io import savemat
    savemat(tmp_path / "log.mat", table)
    import h5py
    with h5py.File(tmp_path / "log.h5", "w") as handle:
        for key, value in table.items():
            handle[key] = value
    for file in files:
        files[file] = load_declared(_declare(tmp_path, file))
    for file, declared in files.items():
        assert declared.rate_hz == pytest.approx(recording.rate_hz, rel=1e-9), file
        assert np.array_equal(declared.gyro_radps, recording.gyro_radps[:keep]), file
        assert np.array_equal(declared.accelerometer_mps2,
                              recording.accelerometer_mps2[:keep]), file
        assert np.array_equal(declared.magnetometer_uT, recording.magnetometer_uT[:keep]), file
        reference = recording.reference_quat[:keep]
        seen = ~np.isnan(reference).any(axis=1)
        assert np.array_equal(seen, ~np.isnan(declared.reference_quat).any(axis=1)), file
        assert np.allclose(declared.reference_quat[seen], reference[seen], atol=1e-15), file
        assert np.array_equal(declared.movement, seen), file


@pytest.mark.slow
def test_a_declared_csv_scores_as_its_npz_does(trial, tmp_path):
    # The same samples through a CSV and a [recording] file, and as the
    # toolkit's own .npz: the broad command's numbers agree to rounding.
    recording, keep = trial
    declared = _declare(tmp_path, _csv(tmp_path, _table(trial)))
    archive = tmp_path / "npz"
    archive.mkdir()
    with np.load(TRIAL) as data:
        arrays = {key: data[key][:keep] if data[key].ndim and len(data[key]) > keep else data[key]
                  for key in data.files}
    arrays["movement"] = ~np.isnan(arrays["opt_quat"]).any(axis=1)
    arrays["movement"][0] = False
    np.savez(archive / f"{declared.stem}.npz", **arrays)
    (archive / "trials.json").write_text(
        '{"groups": [{"name": "recordings", "level": 1}], "trials": {"%s": '
        '{"groups": ["recordings"]}}}' % declared.stem)
    scores = {}
    for label, source in (("declared", declared), ("npz", archive)):
        out = tmp_path / f"out_{label}"
        assert main(["broad", "--broad", str(source), "--estimators", "mekf,madgwick",
                     "--out", str(out), "--quiet"]) == 0
        scores[label] = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    total = [c for c in scores["npz"].columns if c.startswith("total")][0]
    assert np.allclose(scores["declared"][total], scores["npz"][total], rtol=1e-6, atol=1e-9)
    assert np.isfinite(scores["declared"][total]).all()


def _phone(trial, jitter: float = 0.2, seed: int = 1) -> pd.DataFrame:
    """The trial as a phone logs it: the gyro's clock jittered (±``jitter`` of
    a step, times in ms), the accelerometer in g, the magnetometer at a
    quarter of the gyro's rate on its own clock in nT, the reference every
    second sample in x, y, z, w order; one merged table, empty cells where a
    sensor did not read."""
    recording, keep = trial
    table = _table(trial)
    step = 1.0 / recording.rate_hz
    rng = np.random.default_rng(seed)
    t = table["t"] + rng.uniform(-jitter, jitter, keep) * step
    frame = pd.DataFrame({"t_ms": t * 1e3})
    for axis in "xyz":
        frame[f"g{axis}"] = table[f"g{axis}"]
        frame[f"a{axis}"] = table[f"a{axis}"] / 9.80665
        magnetometer = np.full(keep, np.nan)
        magnetometer[::4] = table[f"m{axis}"][::4] * 1e3
        frame[f"m{axis}"] = magnetometer
    for part in "xyzw":
        reference = np.array(table[f"q{part}"])
        reference[1::2] = np.nan
        frame[f"q{part}"] = reference
    return frame


@pytest.mark.slow
def test_a_phone_log_on_its_own_clocks_and_units_reaches_the_scored_table(trial, tmp_path):
    frame = _phone(trial)
    frame.to_csv(tmp_path / "phone.csv", index=False, float_format="%.17g")
    declared = _declare(tmp_path, "phone.csv", time_unit="ms", acc_unit="g", mag_unit="nT",
                        reference='["qx", "qy", "qz", "qw"]', reference_keys='order = "xyzw"')
    declared.write_text(declared.read_text().replace('time = "t"', 'time = "t_ms"'))
    recording = load_declared(declared)
    assert recording.rate_hz == pytest.approx(trial[0].rate_hz, rel=0.02)
    read = np.any(recording.magnetometer_uT != 0, axis=1)
    assert abs(read.mean() - 0.25) < 0.02          # a quarter of the samples, each once
    scores = {}
    for label, source in (("phone", declared),
                          ("one clock", _declare(tmp_path, _csv(tmp_path, _table(trial))))):
        out = tmp_path / label.replace(" ", "_")
        assert main(["broad", "--broad", str(source), "--estimators", "mekf", "--out",
                     str(out), "--quiet"]) == 0
        scored = pd.read_csv(out / "broad_trials.csv")
        scores[label] = float(scored.filter(like="total").iloc[0, 0])
    # The same motion, its magnetometer at a quarter of the rate and each
    # reading up to a fifth of a step late: the MEKF's score moves by far
    # less than a tenth of a degree (measured 1.020° against 1.014°).
    assert abs(scores["phone"] - scores["one clock"]) < 0.1


def test_the_reference_in_euler_angles_and_ned_is_the_same_attitude(trial, tmp_path):
    from scipy.spatial.transform import Rotation
    from sensors.declared_reference import NED_TO_ENU
    recording, keep = trial
    table = _table(trial)
    quat = recording.reference_quat[:keep]
    seen = ~np.isnan(quat).any(axis=1)
    in_ned = Rotation.from_matrix(NED_TO_ENU).inv() * Rotation.from_quat(quat[seen],
                                                                         scalar_first=True)
    angles = np.full((keep, 3), np.nan)
    angles[seen] = in_ned.as_euler("ZYX", degrees=True)
    for i, name in enumerate(("yaw", "pitch", "roll")):
        table[name] = angles[:, i]
    _csv(tmp_path, table)
    declared = load_declared(_declare(
        tmp_path, "log.csv", reference='["yaw", "pitch", "roll"]',
        reference_keys='sequence = "ZYX"\nunit = "deg"\nframe = "NED"'))
    expected = Rotation.from_quat(quat[seen], scalar_first=True)
    got = Rotation.from_quat(declared.reference_quat[seen], scalar_first=True)
    assert np.degrees((expected.inv() * got).magnitude()).max() < 1e-9


@pytest.mark.slow
def test_a_reference_in_other_axes_is_noted_and_a_wrong_sequence_named(trial, tmp_path):
    """The reference's axes turned 20° from the IMU's fit the gyro's turning
    and are said to (every score includes them); Euler angles declared
    extrinsic for intrinsic are refused, naming the sequence that fits."""
    from scipy.spatial.transform import Rotation
    recording, keep = trial
    table = _table(trial, whole=True)
    quat = recording.reference_quat
    seen = ~np.isnan(quat).any(axis=1)
    mounted = np.full_like(quat, np.nan)
    mounted[seen] = (Rotation.from_quat(quat[seen], scalar_first=True) * Rotation.from_euler(
        "x", 20.0, degrees=True)).as_quat(scalar_first=True)
    table.update({f"q{part}": mounted[:, i] for i, part in enumerate("wxyz")})
    angles = np.full((len(quat), 3), np.nan)
    angles[seen] = Rotation.from_quat(quat[seen], scalar_first=True).as_euler("ZYX")
    table.update({name: angles[:, i] for i, name in enumerate(("yaw", "pitch", "roll"))})
    _csv(tmp_path, table)
    # Real rates (noise, a bias) find the 20° within half a degree.
    with pytest.warns(UserWarning, match=r"recording.reference: it turns as the gyro only "
                      r"with its axes turned (19\.[5-9]|20\.[0-4])° from the gyro's"):
        load_declared(_declare(tmp_path, "log.csv"))
    with pytest.raises(InvalidParameterError, match='reference.sequence = .zyx.: makes a '
                       'reference that turns unlike the gyro .*; sequence = "ZYX" would fit'):
        load_declared(_declare(tmp_path, "log.csv", reference='["yaw", "pitch", "roll"]',
                               reference_keys='sequence = "zyx"\nunit = "rad"'))


@pytest.mark.parametrize("change, message", [
    (dict(gyro_unit="rad/s", scale_gyro=180 / math.pi),
     'gyro.unit = .rad/s.: makes the gyro turn gravity 5.\\.. times as fast .*unit = "deg/s"'),
    (dict(gyro_unit="deg/s"),
     'gyro.unit = .deg/s.: makes the gyro turn gravity 5[0-9.]* times slower .*unit = "rad/s"'),
    (dict(gyro_unit="rad/s", scale_gyro=1e6), "gyro.unit = .rad/s.: gives rates up to"),
    (dict(acc_unit="m/s^2", scale_acc=1 / 9.80665),
     'accelerometer.unit = .m/s\\^2.: makes the median .* unit = "g" would fit'),
    (dict(mag_unit="uT", scale_mag=1e3), 'magnetometer.unit = .uT.: .* unit = "nT" would fit'),
    (dict(reference='["qw", "qx", "qy", "nope"]'), "must name a column of the file; it has t, "),
    (dict(back=True), "gyro.time = 't': goes back or repeats at reading 100 \\([0-9.]+ s after "
                      "[0-9.]+ s\\); times must increase"),
    (dict(partly=True), "accelerometer.columns = .*: row 7 is partly empty"),
    (dict(infinite_time=True), "gyro.time = 't': row 100 holds an infinite time \\(inf\\)"),
    (dict(time_unit="minutes"), "time_unit = 'minutes': must be one of s, ms, us, ns"),
    # Times in seconds declared in ms: the clock's unit is named, not the gyro's.
    (dict(time_unit="ms"), 'time_unit = .ms.: makes the gyro read at 2.86e\\+05 Hz, where an '
                           'IMU reads at 1 Hz to 100 kHz; time_unit = "s" would fit'),
    (dict(scale_gyro=0.0), "gyro.columns = .*: hold only zeros: the gyro recorded no rate"),
    # Declarations that pass every range check and turn unlike the gyro
    # (sensors.turning): each names the key and the declaration that fits.
    (dict(reference='["qx", "qy", "qz", "qw"]'),
     'reference.order = .wxyz.: makes a reference that turns unlike the gyro .*; order = '
     '"xyzw" would fit'),
    (dict(inverse=True), 'reference.order = .wxyz.: .* its inverse .* would fit'),
    (dict(mag_columns=[1, 2, 0]), 'magnetometer.axes = .*x.*y.*z.*: turn the field unlike the '
                                  'gyro .*; axes = \\["z", "x", "y"\\] turns it as the gyro'),
])
def test_a_loggers_mistake_is_one_line_and_nothing_is_written(trial, tmp_path, capsys, change,
                                                               message):
    import re
    # The whole trial: its first seconds turn about the vertical only, which
    # turns no gravity and tells nothing of the gyro's unit.
    table = {key: np.array(value, dtype=float) for key, value in _table(trial, True).items()}
    for sensor, prefix in (("gyro", "g"), ("acc", "a"), ("mag", "m")):
        factor = change.pop(f"scale_{sensor}", 1.0)
        for axis in "xyz":
            table[f"{prefix}{axis}"] *= factor
    if change.pop("back", False):
        table["t"][100] = table["t"][98]
    if change.pop("partly", False):
        table["ay"][7] = np.nan
    if change.pop("infinite_time", False):
        table["t"][100] = np.inf
    if change.pop("inverse", False):
        table["qx"], table["qy"], table["qz"] = -table["qx"], -table["qy"], -table["qz"]
    columns = change.pop("mag_columns", [0, 1, 2])
    table["mx"], table["my"], table["mz"] = (table[f"m{'xyz'[i]}"] for i in columns)
    declared = _declare(tmp_path, _csv(tmp_path, table), **change)
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out", str(out),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("attitude-bench: error: log.toml: recording.")
    assert re.search(message, err), err
    assert not out.exists()


def _still_log(seconds: float = 30.0, rate_hz: float = 100.0, carried: float = 0.2) -> dict:
    """A device that never turns: its gyro reads its bias and noise (deg/s),
    its accelerometer gravity tilted 30° and a translation of ``carried``
    m/s² at 0.5 Hz, its magnetometer a constant field (north, dipping 63°),
    its reference one attitude throughout."""
    rng = np.random.default_rng(3)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    tilt = math.radians(30.0)
    # the world's (ENU) up and field in the body, turned 30° about x
    up = 9.81 * np.array([0.0, math.sin(tilt), math.cos(tilt)])
    field = np.array([0.0, 20.0 * math.cos(tilt) - 40.0 * math.sin(tilt),
                      -20.0 * math.sin(tilt) - 40.0 * math.cos(tilt)])
    table = {"t": t}
    for i, axis in enumerate("xyz"):
        table[f"g{axis}"] = (0.1, -0.2, 0.05)[i] + 0.05 * rng.standard_normal(len(t))
        table[f"a{axis}"] = up[i] + carried * np.sin(2 * np.pi * 0.5 * t + i) \
            + 0.02 * rng.standard_normal(len(t))
        table[f"m{axis}"] = field[i] + 0.3 * rng.standard_normal(len(t))
    quat = (math.cos(tilt / 2), math.sin(tilt / 2), 0.0, 0.0)
    table.update({f"q{part}": np.full(len(t), quat[i]) for i, part in enumerate("wxyz")})
    return table


@pytest.mark.slow
def test_a_still_device_carried_is_scored_and_inspected(tmp_path, capsys):
    # A device carried without turning: its accelerometer's translation,
    # read over a few 10 s windows, once passed for gravity turning a
    # hundred times slower than the gyro (a clock "100 times off"), and
    # inspect, guessing rad/s for its deg/s bias, divided by the still
    # reference's zero turning (a traceback)
    declared = _declare(tmp_path, _csv(tmp_path, _still_log(), "still.csv"), gyro_unit="deg/s")
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out", str(out),
                 "--quiet"]) == 0
    scores = pd.read_csv(out / "broad_trials.csv")
    assert scores["total_rmse_deg"].iloc[0] < 1.0
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "still.csv"), "--out", str(tmp_path / "guess")]) == 0
    err = capsys.readouterr().err
    # its gyro's unit is a guess by the rates' size, and said to be
    assert "Traceback" not in err
    assert "gyro: rad/s by the rates' size: the log turns too little for gravity's turning " \
        "to tell its unit (check it)" in err


@pytest.mark.slow      # 4 s
def test_a_log_with_a_gap_is_two_trials_each_scored_as_its_npz(trial, tmp_path, capsys):
    # The gyro's clock stops for 2 s: the file is two parts, each a trial of
    # its own, each scored exactly as the same samples in the toolkit's .npz.
    from sensors.declared import load_parts
    recording, keep = trial
    split = keep // 2
    table = {key: np.array(value, dtype=float) for key, value in _table(trial).items()}
    for part in "wxyz":
        table[f"q{part}"][split] = np.nan         # each part starts without a reference
    table["t"][split:] += 2.0
    declared = _declare(tmp_path, _csv(tmp_path, table))
    with pytest.raises(InvalidParameterError,
                       match="= 't': has 1 gap.*run broad --broad .*, which scores each part"):
        load_declared(declared)
    parts = load_parts(declared)
    assert [p.name for p in parts] == ["log_part1", "log_part2"]
    assert [p.n_samples for p in parts] == [split, keep - split]
    archive = tmp_path / "npz"
    archive.mkdir()
    with np.load(TRIAL) as data:
        arrays = {key: data[key] for key in data.files}
    arrays["opt_quat"] = arrays["opt_quat"].copy()
    arrays["opt_quat"][split] = np.nan
    for name, span in (("log_part1", slice(0, split)), ("log_part2", slice(split, keep))):
        part = {key: value[span] if value.ndim and len(value) == recording.n_samples else value
                for key, value in arrays.items()}
        part["movement"] = ~np.isnan(part["opt_quat"]).any(axis=1)
        np.savez(archive / f"{name}.npz", **part)
    (archive / "trials.json").write_text(
        '{"groups": [{"name": "recordings", "level": 1}], "trials": {"log_part1": '
        '{"groups": ["recordings"]}, "log_part2": {"groups": ["recordings"]}}}')
    scores = {}
    for label, source in (("declared", declared), ("npz", archive)):
        out = tmp_path / f"out_{label}"
        assert main(["broad", "--broad", str(source), "--estimators", "mekf", "--out",
                     str(out), "--quiet"]) == 0
        scores[label] = pd.read_csv(out / "broad_trials.csv").set_index("trial")
        if label == "declared":      # the split is said, with each part's length
            assert re.search(r"note: log.toml: the gyro's clock stops 1 time\(s\) .* started "
                             r"anew: log_part1 \([0-9.]+ s\), log_part2 \([0-9.]+ s\)",
                             capsys.readouterr().err)
    total = [c for c in scores["npz"].columns if c.startswith("total")][0]
    assert len(scores["declared"]) == 2
    assert np.allclose(scores["declared"][total], scores["npz"][total], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("change, message", [
    ("no accelerometer", "declares no .recording.accelerometer.; the IMU filters scored here "
     "need it at least"),
    ("time unit list", "time_unit = \\['s'\\]: must be one of s, ms, us, ns"),
    ("zeros", "accelerometer.columns = .*: hold only zeros, or no reading"),
    ("header only", "gyro.time = 't': holds no rows"),
    ("text cell", "gyro.columns = 'gx': must be one column of numbers; it holds text"),
    ("frame on gyro", "gyro.frame = 'NED': is not a key of the gyro's section"),
    ("lengths", "magnetometer.columns = .*: must be columns of one length"),
    # The one recording given, too short: its own rule, named by its file.
    ("short", "broad = '.*log.toml': has 20 samples; a trial needs at least"),
    # The file's own error, named by the declaration that gave it.
    ("empty file", "log.toml: recording.file = 'log.csv': cannot be read"),
    # The fit's rule, not the key's: the trial's first 40 s turn too little.
    pytest.param("calibrate", "magnetometer.calibrate = True: cannot be done on these "
                 "readings \\(\\d+% of the directions\\): an ellipsoid fit needs readings in "
                 "at least 70%", marks=pytest.mark.slow),
])
def test_a_malformed_declaration_or_file_is_one_line(trial, tmp_path, capsys, change, message):
    import re
    table = _table(trial)
    file = "log.csv"
    if change == "zeros":
        table.update({f"a{axis}": np.zeros(trial[1]) for axis in "xyz"})
    if change == "text cell":
        table["gx"] = np.array(table["gx"], dtype=object)
        table["gx"][5] = "err"
    if change == "header only":
        table = {key: value[:0] for key, value in table.items()}
    if change == "short":
        table = {key: value[2000:2020] for key, value in table.items()}
    if change == "lengths":
        table["mx"] = table["mx"][:100]
        np.savez(tmp_path / "log.npz", **table)
        file = "log.npz"
    else:
        pd.DataFrame(table).to_csv(tmp_path / file, index=False)
    if change == "empty file":
        (tmp_path / file).write_bytes(b"")
    declared = _declare(tmp_path, file)
    text = declared.read_text()
    if change == "calibrate":
        text = text.replace('unit = "uT"', 'unit = "uT"\ncalibrate = true')
    if change == "no accelerometer":
        text = text.split("[recording.accelerometer]")[0] + "[recording.magnetometer]" + \
            text.split("[recording.magnetometer]")[1]
    if change == "time unit list":
        text = text.replace('time_unit = "s"', 'time_unit = ["s"]')
    if change == "frame on gyro":
        text = text.replace('unit = "rad/s"', 'unit = "rad/s"\nframe = "NED"')
    declared.write_text(text)
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out", str(out),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and re.search(message, err), err
    assert not out.exists()


def test_ned_and_interpolation_against_known_attitudes(trial, tmp_path):
    # Fixed cases, not the module's own matrix: NED's identity is the body
    # whose x points north and z down, in ENU x -> (0, 1, 0), z -> (0, 0, -1).
    # (The declared reference alone: an identity reference with the trial's
    # accelerometer would put gravity down, which loading refuses.)
    from scipy.spatial.transform import Rotation
    from sensors.declared_reference import declared_reference
    recording, keep = trial
    times = recording.time_s[:keep]
    reference = declared_reference(tmp_path / "log.toml", times, times,
                                   np.tile([1.0, 0.0, 0.0, 0.0], (keep, 1)), {"frame": "NED"})
    matrix = Rotation.from_quat(reference[10], scalar_first=True).as_matrix()
    assert np.allclose(matrix @ [1, 0, 0], [0, 1, 0]) and np.allclose(matrix @ [0, 0, 1],
                                                                     [0, 0, -1])
    # Every second reference reading dropped: the interpolated ones are within
    # a tenth of a degree of the true ones (the slow trial; measured 0.085°).
    table = _table(trial)
    for part in "wxyz":
        table[f"q{part}"] = np.array(table[f"q{part}"])
        table[f"q{part}"][1::2] = np.nan
    _csv(tmp_path, table, "half.csv")
    half = load_declared(_declare(tmp_path, "half.csv"))
    truth = recording.reference_quat[:keep]
    both = ~np.isnan(truth).any(axis=1) & ~np.isnan(half.reference_quat).any(axis=1)
    both[::2] = False                                       # the interpolated samples only
    error = (Rotation.from_quat(truth[both], scalar_first=True).inv()
             * Rotation.from_quat(half.reference_quat[both], scalar_first=True)).magnitude()
    assert both.sum() > keep // 3 and np.degrees(error.max()) < 0.1


def test_integer_epoch_nanoseconds_keep_the_clock(trial, tmp_path):
    recording, keep = trial
    table = _table(trial)
    step_ns = int(round(1e9 / recording.rate_hz))
    table["t"] = 1_733_000_000_000_000_000 + step_ns * np.arange(keep, dtype=np.int64)
    np.savez(tmp_path / "log.npz", **table)
    declared = load_declared(_declare(tmp_path, "log.npz", time_unit="ns"))
    assert declared.rate_hz == pytest.approx(1e9 / step_ns, rel=1e-12)


@pytest.mark.slow      # the per-run replay of a whole trial, twice: 5 s
def test_replay_takes_a_declared_recording_as_its_npz(trial, tmp_path, capsys):
    # The gyro-only replay (a pseudo star tracker made from the reference)
    # on a declared CSV and on the same samples as the toolkit's .npz, its
    # movement flagged after the rest that replay finds in the CSV.
    recording, _ = trial
    keep = int(60 * recording.rate_hz)
    declared = _declare(tmp_path, _csv(tmp_path, _table((recording, keep))))
    with np.load(TRIAL) as data:
        arrays = {key: data[key][:keep] if data[key].ndim and len(data[key]) > keep else data[key]
                  for key in data.files}
    found = open_dataset(str(declared))[0].movement
    assert found.any() and not found[:int(39 * recording.rate_hz)].any()
    arrays["movement"] = found
    np.savez(tmp_path / "same.npz", **arrays)
    summaries = {}
    for label, source in (("declared", declared), ("npz", tmp_path / "same.npz")):
        out = tmp_path / f"replay_{label}"
        assert main(["replay", "--dataset", str(source), "--estimators", "mekf", "--out",
                     str(out), "--quiet"]) == 0
        summaries[label] = pd.read_csv(out / "summary.csv").set_index("estimator")
    columns = ["rms_movement_deg", "mean_deg", "max_deg", "final_deg", "final_bias_error_degps"]
    assert np.allclose(summaries["declared"][columns], summaries["npz"][columns], rtol=1e-6)
    assert np.isfinite(summaries["declared"][columns]).all(axis=None)


def test_replay_finds_the_rest_a_declared_recording_begins_with(trial, tmp_path):
    """Trial 02's first 60 s declared: no key flags its rest, and replay
    finds it as VQF finds rest (Laidig & Seel 2023, §3.4) within half a
    second of the authors' flag (their movement begins at 40.07 s); a log
    that moves from its first sample keeps every referenced sample."""
    recording, _ = trial
    keep = int(60 * recording.rate_hz)
    table = _table((recording, keep))
    with pytest.warns(UserWarning, match="its first 39.7 s are at rest"):
        found = open_dataset(str(_declare(tmp_path, _csv(tmp_path, table))))[0].movement
    flagged = recording.movement[:keep]
    begins = [np.argmax(flags) / recording.rate_hz for flags in (found, flagged)]
    assert abs(begins[0] - begins[1]) < 0.5, begins
    late = {**table, **{f"a{axis}": np.concatenate([[np.nan, np.nan], np.asarray(
        table[f"a{axis}"])[2:]]) for axis in "xyz"}}     # the accelerometer's first reading late
    with pytest.warns(UserWarning, match="its first 39.7 s are at rest"):
        open_dataset(str(_declare(tmp_path, _csv(tmp_path, late, "late.csv"))))
    # A log that moves from its first sample, its reference begun a second
    # later: no rest at all (not the samples before the reference), so no
    # bias at rest to judge the filters' against.
    moving = {key: np.array(value)[int(41 * recording.rate_hz):] for key, value in table.items()}
    for part in "wxyz":
        moving[f"q{part}"][:int(recording.rate_hz)] = np.nan
    moved = open_dataset(str(_declare(tmp_path, _csv(tmp_path, moving, "moving.csv"))))[0]
    assert moved.movement.all() and np.isnan(moved.rest_gyro_mean_radps()).all()
    # A log at rest throughout (its first 35 s): nothing moves after its
    # rest, and every sample is scored (its last fraction of a second had
    # been scored alone, as "the movement after the rest")
    rested = {key: np.array(value)[:int(35 * recording.rate_hz)] for key, value in table.items()}
    with pytest.warns(UserWarning, match="it is at rest throughout"):
        still = open_dataset(str(_declare(tmp_path, _csv(tmp_path, rested, "still.csv"))))[0]
    assert still.movement.all()


def test_read_table_names_a_file_it_cannot_read(tmp_path):
    (tmp_path / "log.xlsx").write_text("not a table")
    with pytest.raises(InvalidParameterError, match=r"must be .csv \(or .csv.gz\), .parquet, .npz"):
        read_table(tmp_path / "log.xlsx")
    (tmp_path / "log.npz").write_text("not an archive")
    with pytest.raises(InvalidParameterError, match="cannot be read"):
        read_table(tmp_path / "log.npz")


def test_an_empty_archive_is_said_to_have_no_column(tmp_path, capsys):
    np.savez(tmp_path / "log.npz")                        # a logger that saved nothing
    declared = _declare(tmp_path, "log.npz")
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "it has no column at all (an empty file)" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow      # 3 s
def test_a_sensor_mostly_rejected_is_noted_below_the_table(trial, tmp_path, capsys):
    """A field whose norm swings ±50 % every 2 s (a magnet carried beside the
    IMU) is rejected most of the time by the MEKF's norm test; the table's
    share is easily missed, so a note says what it leaves to the gyro. A
    field the filters take raises none."""
    recording, keep = trial
    table = _table(trial)
    t = np.asarray(table["t"]) - table["t"][0]
    swing = 1.0 + 0.5 * np.sin(2 * np.pi * t / 2.0)
    for axis in "xyz":
        table[f"m{axis}"] = np.asarray(table[f"m{axis}"]) * swing
    declared = _declare(tmp_path, _csv(tmp_path, table))
    args = ["broad", "--broad", str(declared), "--estimators", "mekf", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "swing")]) == 0
    out = capsys.readouterr().out
    rejected = pd.read_csv(tmp_path / "swing" / "broad_trials.csv")[
        "rejected_magnetometer_share"].iloc[0]
    assert rejected > 0.5
    assert f"trial log: mekf rejected up to {100 * rejected:.3g} % of the magnetometer's " \
        "readings: their heading there rests on the gyro alone" in out
    _csv(tmp_path, _table(trial))
    assert main([*args, "--out", str(tmp_path / "steady")]) == 0
    assert "rests on the gyro alone" not in capsys.readouterr().out


@pytest.mark.slow     # the whole trial through the command twice (6 s): in .ci/run's slow group
def test_a_clipped_accelerometer_is_noted(trial, tmp_path, capsys):
    """An accelerometer clipped at its rail (here ±11 m/s², below the
    trial's peaks) is said to be; the same log unclipped raises no note."""
    table = _table(trial, whole=True)
    _csv(tmp_path, table)
    args = ["broad", "--broad", str(_declare(tmp_path, "log.csv")), "--estimators",
            "dead-reckoning", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "whole")]) == 0
    assert "its rail (clipped)" not in capsys.readouterr().err
    rail = 11.0
    for axis in "xyz":
        table[f"a{axis}"] = np.clip(table[f"a{axis}"], -rail, rail)
    count = int(np.count_nonzero(np.any(np.abs(np.column_stack(
        [table[f"a{axis}"] for axis in "xyz"])) == rail, axis=1)))
    assert count >= 20
    _csv(tmp_path, table)
    assert main([*args, "--out", str(tmp_path / "clipped")]) == 0
    assert f"trial log: {count} accelerometer readings at ±11 m/s², its rail (clipped)" in \
        capsys.readouterr().err


@pytest.mark.slow
def test_replay_notes_a_clipped_gyro_and_only_its_gyro(trial, tmp_path, capsys):
    # replay reads the gyro alone: its clipping is said, as broad says it,
    # and the accelerometer's, which it does not read, is not
    table = _table(trial, whole=True)
    # rails below the trial's peaks: 0.5 rad/s, and 9.5 m/s² (gravity's axis at rest)
    for prefix, rail in (("g", 0.5), ("a", 9.5)):
        for axis in "xyz":
            table[f"{prefix}{axis}"] = np.clip(table[f"{prefix}{axis}"], -rail, rail)
    from benchmarks.experiments.inspection import clipped
    for prefix in "ga":
        assert clipped(np.column_stack([table[f"{prefix}{axis}"] for axis in "xyz"]))[0] >= 20
    _csv(tmp_path, table)
    assert main(["replay", "--dataset", str(_declare(tmp_path, "log.csv")), "--estimators",
                 "dead-reckoning", "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "gyro readings at ±0.5 rad/s, its rail (clipped)" in err
    assert "accelerometer readings at" not in err


@settings(max_examples=60, deadline=None)
@given(rate=st.floats(20.0, 2000.0), quantum_ms=st.sampled_from([0.0, 0.1, 1.0]),
       drops=st.sampled_from([0.0, 0.05, 0.2]), seed=st.integers(0, 2 ** 32 - 1))
def test_the_clock_is_fitted_through_rounded_times_and_dropped_samples(rate, quantum_ms, drops,
                                                                       seed):
    """A uniform clock of ``rate`` Hz, its times rounded to a quantum q (a
    logger's whole milliseconds), a share ``drops`` of its samples dropped,
    never two in a row: each kept sample's step and the period are found.
    Rounding moves an interval by at most q and the median by at most q:
    with q <= p/10 an interval of one or two periods reads as 0.82-1.22 or
    1.73-2.33 medians, so its count is exact; without drops the mean is the
    period and q < p/2 keeps each count at 1. The least-squares slope over
    n steps then errs by at most (q/2)·Σ|x - x̄| / Σ(x - x̄)² ≈ 1.5 q/n."""
    from sensors.clocks import clock_period, clock_steps
    period, quantum = 1.0 / rate, quantum_ms * 1e-3
    assume(quantum <= period / 10 or (drops == 0.0 and quantum < period / 2))
    rng = np.random.default_rng(seed)
    dropped = rng.random(400) < drops
    dropped[1:] &= ~dropped[:-1]
    dropped[[0, -1]] = False
    steps = np.flatnonzero(~dropped)
    times = 12.5 + steps * period
    if quantum:
        times = np.round(times / quantum) * quantum
    found, fitted = clock_steps(times)
    np.testing.assert_array_equal(found, steps)
    span = steps[-1]
    assert abs(fitted - period) * span <= 1.5 * quantum + 1e-9
    # clock_period is the median where the fit agrees with it to 1 ppm
    assert abs(clock_period(times) - period) * span <= 1.5 * quantum + 1e-6 * period * span + 1e-9


@settings(max_examples=40, deadline=None)
@given(rate=st.floats(20.0, 2000.0), drops=st.sampled_from([0.0, 0.05]),
       pauses=st.integers(1, 30), seed=st.integers(0, 2 ** 32 - 1))
def test_a_steady_clock_with_pauses_keeps_its_period(rate, drops, pauses, seed):
    """A steady clock with samples dropped and paused ``pauses`` times, each
    pause resuming at a new phase: the loader splits it at the pauses and
    finds each part steady, so its period is the clock's. One line fitted
    across the pauses had called it unsteady and told the mean interval
    (190 Hz for a 200 Hz clock with 5 % dropped and 10 to 30 pauses)."""
    from sensors.clocks import clock_period
    period = 1.0 / rate
    rng = np.random.default_rng(seed)
    kept = rng.random(3000) >= drops
    kept[1:] |= ~kept[:-1]                       # never two dropped in a row
    kept[[0, -1]] = True
    times = np.flatnonzero(kept) * period
    for start in rng.choice(np.arange(10, len(times) - 10), pauses, replace=False):
        times[start:] += (5.0 + rng.random()) * period * 10
    assert clock_period(times) == pytest.approx(period, rel=1e-9)


@pytest.mark.slow      # 4 s
def test_a_clock_in_integer_milliseconds_scores_as_the_exact_one(trial, tmp_path, capsys):
    """BROAD's 286 Hz in whole milliseconds (intervals of 3 and 4 ms, median
    3): the rate is fitted (286 Hz, not 333), and the scores are those of
    the exact clock to a small part of a degree."""
    table = _table(trial)
    exact = _declare(tmp_path, _csv(tmp_path, table, "exact.csv"))
    table["t"] = np.floor(np.asarray(table["t"]) * 1000.0)
    rounded = _declare(tmp_path, _csv(tmp_path, table, "ms.csv"), time_unit="ms")
    scores = {}
    for path in (exact, rounded):
        (recording,) = load_parts(path)
        assert recording.rate_hz == pytest.approx(trial[0].rate_hz, rel=2e-3)
        out = tmp_path / path.stem
        assert main(["broad", "--broad", str(path), "--estimators", "mekf", "--out", str(out),
                     "--quiet"]) == 0
        scores[path.stem] = pd.read_csv(out / "broad_trials.csv")["total_rmse_deg"].iloc[0]
    assert abs(scores["ms"] - scores["exact"]) < 0.1 * scores["exact"], scores


def test_a_dropped_gyro_sample_is_put_back_with_the_rate_before_it(trial, tmp_path):
    table = _table(trial)
    kept = np.ones(len(table["t"]), dtype=bool)
    kept[[100, 205, 333]] = False
    declared = _declare(tmp_path, _csv(tmp_path, {k: np.asarray(v)[kept] for k, v in
                                                  table.items()}, "drops.csv"))
    with pytest.warns(UserWarning, match="3 gyro sample.s. missing between readings"):
        (recording,) = load_parts(declared)
    gyro = np.asarray([table[f"g{axis}"] for axis in "xyz"]).T
    assert recording.n_samples == len(kept)
    np.testing.assert_array_equal(recording.gyro_radps[kept], gyro[kept])
    np.testing.assert_array_equal(recording.gyro_radps[[100, 205, 333]], gyro[[99, 204, 332]])
    assert recording.rate_hz == pytest.approx(trial[0].rate_hz, rel=1e-9)


def test_a_part_shorter_than_a_turning_block_loads(trial, tmp_path):
    """Two gaps 10 samples apart (35 ms at 286 Hz, shorter than the turning
    checks' 0.1 s block): the short part loads as one of three, no crash."""
    table = _table(trial)
    table["t"] = np.asarray(table["t"]) + np.where(np.arange(len(table["t"])) >= 600, 1.0, 0.0) \
        + np.where(np.arange(len(table["t"])) >= 610, 1.0, 0.0)
    parts = load_parts(_declare(tmp_path, _csv(tmp_path, table, "short.csv")))
    assert [part.n_samples for part in parts] == [600, 10, len(table["t"]) - 610]


@pytest.mark.slow      # 3.5 s
def test_an_accelerometer_and_a_magnetometer_never_on_one_sample_run(trial, tmp_path):
    """The accelerometer at half the gyro's rate, the magnetometer at a
    quarter, on samples the accelerometer skips: no sample holds both, and
    the start and the field's reference pair each field reading with the
    latest accelerometer one. It scores as the same log with the field read
    on the accelerometer's samples to a tenth of a degree."""
    table = _table(trial)
    rows = np.arange(len(table["t"]))
    scores = {}
    for name, mag_rows in (("apart", rows % 4 == 1), ("together", rows % 4 == 0)):
        logged = {**table,
                  **{f"a{axis}": np.where(rows % 2 == 0, table[f"a{axis}"], np.nan)
                     for axis in "xyz"},
                  **{f"m{axis}": np.where(mag_rows, table[f"m{axis}"], np.nan)
                     for axis in "xyz"}}
        path = _declare(tmp_path, _csv(tmp_path, logged, f"{name}.csv"))
        (recording,) = load_parts(path)
        shared = np.any(recording.accelerometer_mps2 != 0, axis=1) \
            & np.any(recording.magnetometer_uT != 0, axis=1)
        assert shared.any() == (name == "together")
        out = tmp_path / f"out_{name}"
        assert main(["broad", "--broad", str(path), "--estimators", "mekf", "--out", str(out),
                     "--quiet"]) == 0
        scores[name] = pd.read_csv(out / "broad_trials.csv")["total_rmse_deg"].iloc[0]
    assert abs(scores["apart"] - scores["together"]) < 0.1, scores


@pytest.mark.parametrize("change, frame", [("frame", "NED"), ("sign", "ENU")])
def test_gravity_turned_down_by_the_reference_is_refused_in_one_line(trial, tmp_path, change,
                                                                     frame):
    """A reference in the other frame than declared, or an accelerometer that
    logs acceleration (gravity read down, as Core Motion's): either puts the
    accelerometer's gravity down in the world, which cannot be."""
    table = _table(trial)
    if change == "sign":
        for axis in "xyz":
            table[f"a{axis}"] = -np.asarray(table[f"a{axis}"])
    keys = 'frame = "NED"' if change == "frame" else ""
    path = _declare(tmp_path, _csv(tmp_path, table), reference_keys=keys)
    with pytest.raises(InvalidParameterError) as refused:
        load_declared(path)
    message = str(refused.value)
    assert f"recording.reference.frame = '{frame}': puts the accelerometer's gravity down" \
        in message and "\n" not in message
    assert "axes = [\"-x\", \"-y\", \"-z\"]" in message


@pytest.mark.slow        # 4 s: three files written and a trial scored
def test_one_file_per_sensor_is_one_recording(trial, tmp_path, capsys):
    """A logger that writes one file per sensor (phone apps' Gyroscope.csv,
    Accelerometer.csv, …, integer nanosecond times): each section names its
    own file, and the recording is the one the merged table declares, to
    the bit; inspect reads each file, and a missing one is one line."""
    table = _table(trial)
    merged = load_declared(_declare(tmp_path, _csv(tmp_path, table)))
    stamps = np.round(np.asarray(table["t"]) * 1e9).astype(np.int64)
    for prefix, sensor in (("g", "gyro"), ("a", "accelerometer"), ("m", "magnetometer"),
                           ("q", "reference")):
        axes = "wxyz" if prefix == "q" else "xyz"
        frame = pd.DataFrame({"time": stamps, **{f"{prefix}{axis}": np.asarray(
            table[f"{prefix}{axis}"]) for axis in axes}})
        _csv_ints(tmp_path / f"{sensor}.csv", frame)
    sections = "\n".join(
        f'[recording.{sensor}]\nfile = "{sensor}.csv"\ntime = "time"\ncolumns = {columns}\n'
        + (f'unit = "{unit}"\n' if unit else "")
        for sensor, columns, unit in (
            ("gyro", '["gx", "gy", "gz"]', "rad/s"), ("accelerometer", '["ax", "ay", "az"]',
                                                      "m/s^2"),
            ("magnetometer", '["mx", "my", "mz"]', "uT"),
            ("reference", '["qw", "qx", "qy", "qz"]', None)))
    declared = tmp_path / "apart.toml"
    declared.write_text('[recording]\ntime_unit = "ns"\n\n' + sections)
    apart = load_declared(declared)
    for field in ("gyro_radps", "accelerometer_mps2", "magnetometer_uT", "reference_quat"):
        np.testing.assert_allclose(getattr(apart, field), getattr(merged, field), rtol=0,
                                   atol=1e-12, equal_nan=True, err_msg=field)
    assert apart.rate_hz == pytest.approx(merged.rate_hz, rel=1e-6)
    assert main(["inspect", str(declared)]) == 0
    out = capsys.readouterr().out
    assert all(f"{sensor}.csv:" in out for sensor in ("gyro", "magnetometer", "reference"))
    from benchmarks.experiments.replay import dataset_source
    assert dataset_source(str(declared))[0] == "recording"        # replay --tuned's key
    assert main(["broad", "--broad", str(declared), "--estimators", "mekf", "--out",
                 str(tmp_path / "scored"), "--quiet"]) == 0
    scores = pd.read_csv(tmp_path / "scored" / "broad_trials.csv")["total_rmse_deg"]
    assert np.isfinite(scores).all()
    (tmp_path / "magnetometer.csv").unlink()
    with pytest.raises(InvalidParameterError, match="recording.magnetometer.file = "
                       "'magnetometer.csv': is not a file"):
        load_declared(declared)


def _csv_ints(path: Path, frame: pd.DataFrame) -> None:
    """``frame`` as a CSV: integer columns as integers, floats as their
    shortest exact text."""
    columns = [frame[name].astype(str).tolist() if frame[name].dtype.kind in "iu"
               else list(_fields(frame[name].to_numpy(dtype=float))) for name in frame]
    path.write_text(",".join(frame.columns) + "\n"
                    + "\n".join(",".join(row) for row in zip(*columns)) + "\n")


def test_every_sensor_in_a_mirrored_order_is_refused(trial, tmp_path):
    """x and z swapped in every sensor (a logger's z, y, x written as x, y,
    z): each sensor turns with the others, but in a left-handed frame,
    where ω × v changes its sign: gravity turns against the gyro's
    prediction (correlation -1), which the axes check, blind to a common
    mirror, let through (128° for the MEKF)."""
    table = _table(trial, whole=True)
    for prefix in "gam":
        table[f"{prefix}x"], table[f"{prefix}z"] = table[f"{prefix}z"], table[f"{prefix}x"]
    with pytest.raises(InvalidParameterError) as refused:
        load_declared(_declare(tmp_path, _csv(tmp_path, table)))
    message = str(refused.value)
    assert "recording.gyro.columns = ['gx', 'gy', 'gz']: turn gravity the other way" in message
    assert "left-handed" in message and "\n" not in message


def test_an_accelerometer_with_two_axes_swapped_is_refused(trial, tmp_path):
    """x and z swapped in the accelerometer alone: gravity's turning no
    longer correlates with the gyro's prediction (-0.04; 0.48 to 0.87 for
    BROAD's 30 trials as logged), and the right order does (0.85): its axes
    are named with that order (it passed, the magnetometer's thresholds
    asking 0.9 of another order)."""
    table = _table(trial, whole=True)
    table["ax"], table["az"] = table["az"], table["ax"]
    with pytest.raises(InvalidParameterError) as refused:
        load_declared(_declare(tmp_path, _csv(tmp_path, table)))
    message = str(refused.value)
    assert "recording.accelerometer.axes = ['x', 'y', 'z']: turn gravity unlike" in message
    assert 'axes = ["z", "y", "x"]' in message and "left-handed" not in message, message


@pytest.mark.parametrize("unit, scale", [("m/s^2", 1.0), ("g", 1.0 / 9.80665)])
def test_an_accelerometer_without_gravity_is_refused_whatever_its_unit(trial, tmp_path, unit,
                                                                        scale):
    """A phone's user acceleration (gravity taken out) reads near zero at
    rest: no unit makes it gravity, and none is offered (unit = "g" was,
    and then scored 141°)."""
    table = _table(trial)
    for axis in "xyz":
        values = np.asarray(table[f"a{axis}"])
        table[f"a{axis}"] = (values - np.median(values)) * scale
    with pytest.raises(InvalidParameterError) as refused:
        load_declared(_declare(tmp_path, _csv(tmp_path, table), acc_unit=unit))
    message = str(refused.value)
    assert "recording.accelerometer.columns = ['ax', 'ay', 'az']: hold no gravity" in message
    assert "would fit" not in message and "\n" not in message
