"""A 6-axis IMU (gyro and accelerometer, no magnetometer: an MPU-6050, a
drone's flight log, EuRoC's) as a first-class input of ``broad``: the
complementary filters' IMU updates as Madgwick's C code writes them, the
peers fed no field, every filter scored on its inclination (its heading is
its gyro's, from an arbitrary start), the filters that need a field left
out of the defaults with a note and refused by name."""
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from benchmarks.broad.inputs import initial_attitude
from benchmarks.broad.metric import errors_deg, without_heading
from benchmarks.cli import main
from benchmarks.engine.recorded import run_recorded
from dynamics.handheld import HandheldMotion
from dynamics.quaternion import quat_from_rotvec, to_rotation
from estimators import resolve_estimator
from estimators.complementary import madgwick_step, mahony_step
from sensors.handheld import simulated_recording
from sensors.vector import VectorReadings

#: A short hand-held motion: 35 s at 100 Hz.
MOTION = HandheldMotion(rate_hz=100.0, rest_s=3.0, moving_s=30.0, final_rest_s=2.0,
                        taper_s=2.0)
UP = np.array([0.0, 0.0, 1.0])


def c_code_imu_gradient(q, acc):
    """``MadgwickAHRSupdateIMU``'s corrective step, as its C code expands it
    (x-io's MadgwickAHRS.c, 2011), in double precision."""
    q0, q1, q2, q3 = q
    ax, ay, az = np.asarray(acc) / np.linalg.norm(acc)
    s0 = 4 * q0 * q2 * q2 + 2 * q2 * ax + 4 * q0 * q1 * q1 - 2 * q1 * ay
    s1 = 4 * q1 * q3 * q3 - 2 * q3 * ax + 4 * q0 * q0 * q1 - 2 * q0 * ay - 4 * q1 \
        + 8 * q1 * q1 * q1 + 8 * q1 * q2 * q2 + 4 * q1 * az
    s2 = 4 * q0 * q0 * q2 + 2 * q0 * ax + 4 * q2 * q3 * q3 - 2 * q3 * ay - 4 * q2 \
        + 8 * q2 * q1 * q1 + 8 * q2 * q2 * q2 + 4 * q2 * az
    s3 = 4 * q1 * q1 * q3 - 2 * q1 * ax + 4 * q2 * q2 * q3 - 2 * q2 * ay
    return np.array([s0, s1, s2, s3])


unit_quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda v: np.linalg.norm(v) > 0.1).map(lambda v: tuple(np.asarray(v) / np.linalg.norm(v)))
readings = st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3).filter(
    lambda v: np.linalg.norm(v) > 0.1).map(tuple)


@settings(max_examples=200, deadline=None)
@given(q=unit_quaternions, acc=readings, beta=st.floats(0.01, 1.0))
def test_madgwicks_imu_step_is_his_c_codes(q, acc, beta):
    # Without a field reading the step corrects with gravity alone, by the
    # C code's normalised gradient (the MARG's gravity terms, expanded
    # there): the same quaternion to 1e-12.
    dt = 0.01
    gradient = c_code_imu_gradient(q, acc)
    # no rotation: the step is the correction alone; where the quaternion is
    # about level the normalised gradient is rounding's direction: not tested
    assume(np.linalg.norm(gradient) > 1e-6)
    expected = np.asarray(q) - beta * gradient / np.linalg.norm(gradient) * dt
    expected /= np.linalg.norm(expected)
    got = madgwick_step(q, (0.0, 0.0, 0.0), acc, (0.0, 0.0, 0.0), beta, dt, False)
    assert np.allclose(got, expected, atol=1e-12, rtol=0.0)


@settings(max_examples=30, deadline=None)
@given(tilt=st.lists(st.floats(-1.2, 1.2), min_size=3, max_size=3))
def test_the_imu_steps_level_a_still_tilted_imu(tilt):
    # A still IMU, tilted by any rotation of up to 2 rad: from the identity,
    # both filters' IMU updates bring its inclination (the body's up) to
    # the truth; the heading is left to the gyro. Madgwick's normalised
    # step moves the quaternion by β·dt each sample, a rotation of 2β·dt:
    # it ends within two such steps of it; Mahony's converges (0.01°).
    beta, dt = 0.05, 0.01
    truth = to_rotation(quat_from_rotvec(np.asarray(tilt)))
    acc = tuple(truth.inv().apply(UP) * 9.81)
    q_madgwick = q_mahony = (1.0, 0.0, 0.0, 0.0)
    integral = (0.0, 0.0, 0.0)
    for _ in range(4000):
        q_madgwick = madgwick_step(q_madgwick, (0.0, 0.0, 0.0), acc, (0.0, 0.0, 0.0), beta,
                                   dt, False)
        q_mahony, integral = mahony_step(q_mahony, integral, (0.0, 0.0, 0.0), acc,
                                         (0.0, 0.0, 0.0), 2.0, 0.0, 0.01)
    for q, bound in ((q_madgwick, math.degrees(4 * beta * dt)), (q_mahony, 0.01)):
        up = to_rotation(q).inv().apply(UP)          # the body's up as estimated (NWU's up)
        angle = math.degrees(math.acos(np.clip(up @ truth.inv().apply(UP), -1.0, 1.0)))
        assert angle < bound, (q, angle)


def test_without_an_accelerometer_reading_the_steps_integrate_the_rate_alone():
    # Madgwick's C code computes no feedback without an accelerometer
    # reading, a field reading or not.
    q, gyro = (1.0, 0.0, 0.0, 0.0), (0.1, -0.2, 0.3)
    alone = madgwick_step(q, gyro, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5, 0.01, False)
    assert madgwick_step(q, gyro, (0.0, 0.0, 0.0), (20.0, 1.0, -40.0), 0.5, 0.01, False) == alone
    assert alone != q
    assert madgwick_step(q, gyro, (1.0, 0.0, 9.8), (0.0, 0.0, 0.0), 0.5, 0.01, False) != alone


@pytest.fixture(scope="module")
def six_axis():
    recording = simulated_recording(3, MOTION)
    n = recording.n_samples
    vectors = (VectorReadings(sensor="accelerometer", body=recording.accelerometer_mps2,
                              reference=np.tile([0.0, 0.0, 9.80665], (n, 1)),
                              available=np.ones(n, dtype=bool), variance=np.full(n, 0.09),
                              unit="m/s^2"),)
    return recording, vectors


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf", "fusion"])
def test_each_path_runs_a_six_axis_recording_as_the_per_run_class(six_axis, name):
    # The compiled complementary filters and the peers' batch calls are fed
    # no field, as their per-run classes are: the same estimates to 1e-9.
    pytest.importorskip("vqf" if name == "vqf" else "imufusion" if name == "fusion" else "numpy")
    recording, vectors = six_axis
    start = initial_attitude(recording.accelerometer_mps2[0], None,
                             {"accelerometer": np.array([0.0, 0.0, 9.80665])})
    estimator = resolve_estimator(name)(dt=recording.dt, initial_attitude=start)
    fast = run_recorded(estimator, recording.gyro_radps, vectors)
    assert fast.path in ("compiled", "batch")
    n = recording.n_samples
    slow = estimator.run(recording.gyro_radps, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
                         np.zeros(n, dtype=bool), vectors=vectors)
    difference = np.minimum(np.abs(fast.estimates - slow).max(axis=1),
                            np.abs(fast.estimates + slow).max(axis=1))
    assert difference.max() < 1e-9


def test_the_start_without_a_field_is_level_with_the_first_reading():
    # The smallest rotation that turns the accelerometer's reading up: up
    # exactly, and no turn about the vertical for a level reading.
    acc = np.array([1.0, -2.0, 9.5])
    start = initial_attitude(acc, None, {"accelerometer": np.array([0.0, 0.0, 9.80665])})
    assert np.allclose(to_rotation(start).apply(acc / np.linalg.norm(acc)), UP, atol=1e-12)
    level = initial_attitude(np.array([0.0, 0.0, 9.8]), None,
                             {"accelerometer": np.array([0.0, 0.0, 9.80665])})
    assert np.allclose(level, [1.0, 0.0, 0.0, 0.0], atol=1e-12)


def _declared_log(folder, recording, magnetometer: bool, reference: bool = True) -> str:
    """``recording`` as a CSV and its ``[recording]`` declaration, with or
    without its magnetometer and its reference; the declaration's path."""
    columns = {"t": np.arange(recording.n_samples) / recording.rate_hz}
    for prefix, channel in (("g", recording.gyro_radps), ("a", recording.accelerometer_mps2),
                            ("m", recording.magnetometer_uT)):
        columns.update({prefix + axis: channel[:, i] for i, axis in enumerate("xyz")})
    columns.update({"q" + part: recording.reference_quat[:, i] for i, part in enumerate("wxyz")})
    folder.mkdir(exist_ok=True)
    pd.DataFrame(columns).to_csv(folder / "log.csv", index=False)
    sections = ['[recording]\nfile = "log.csv"\n',
                '[recording.gyro]\ntime = "t"\ncolumns = ["gx", "gy", "gz"]\nunit = "rad/s"\n',
                '[recording.accelerometer]\ntime = "t"\ncolumns = ["ax", "ay", "az"]\n'
                'unit = "m/s^2"\n',
                '[recording.reference]\ntime = "t"\ncolumns = ["qw", "qx", "qy", "qz"]\n'
                'order = "wxyz"\n'][:4 if reference else 3]
    if magnetometer:
        sections.append('[recording.magnetometer]\ntime = "t"\ncolumns = ["mx", "my", "mz"]\n'
                        'unit = "uT"\n')
    (folder / "log.toml").write_text("\n".join(sections))
    return str(folder / "log.toml")


@pytest.fixture(scope="module")
def broad_runs(tmp_path_factory):
    """``broad``'s trial table on the same recording declared with and
    without its magnetometer."""
    recording = simulated_recording(3, MOTION)
    root = tmp_path_factory.mktemp("six_axis")
    tables = {}
    for magnetometer in (True, False):
        toml = _declared_log(root / f"mag{magnetometer}", recording, magnetometer)
        out = root / f"out{magnetometer}"
        argv = ["broad", "--broad", toml, "--out", str(out), "--quiet"]
        if magnetometer:        # the 6-axis run takes the default list
            argv += ["--estimators", "dead-reckoning,mekf,madgwick,mahony"]
        assert main(argv) == 0
        tables[magnetometer] = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    return tables


@pytest.mark.slow
def test_broad_scores_a_six_axis_log_on_its_inclination(broad_runs):
    # Every filter runs without a field and is scored on its inclination:
    # no total or heading score (its heading is the gyro's from an
    # arbitrary start), dead reckoning's included; TRIAD and offline VQF,
    # which need a field, are left out of the default list.
    six = broad_runs[False]
    assert {"triad", "vqf-offline"}.isdisjoint(six.index)
    # and the twins that are, without a field, the same filter under two labels
    assert {"madgwick-broad", "vqf-6d"}.isdisjoint(six.index)
    assert {"dead-reckoning", "mekf", "mekf-smoother", "usque", "madgwick",
            "mahony"} <= set(six.index)
    assert six[["total_rmse_deg", "heading_rmse_deg"]].isna().all().all()
    assert np.isfinite(six["inclination_rmse_deg"]).all()
    assert six[["rejected_magnetometer", "rejected_magnetometer_share"]].isna().all().all()
    kalman = six.loc[["mekf", "mekf-smoother", "usque"], "inclination_rmse_deg"]
    assert kalman.max() < six.loc["dead-reckoning", "inclination_rmse_deg"] / 2


def test_a_six_axis_logs_inclination_is_the_nine_axis_logs(broad_runs):
    # The field corrects the heading only (the MEKF's heading-only model)
    # or mostly (Madgwick, Mahony): without it, the inclination is about
    # what it is with it — within a third, and 0.2° — on the same readings.
    nine, six = broad_runs[True], broad_runs[False]
    for name in ("mekf", "madgwick", "mahony"):
        with_field = nine.loc[name, "inclination_rmse_deg"]
        without = six.loc[name, "inclination_rmse_deg"]
        assert without < 1.34 * with_field + 0.2, (name, with_field, without)
    assert math.isfinite(nine.loc["mekf", "total_rmse_deg"])


def test_an_estimator_that_needs_a_field_is_refused_by_name(tmp_path, capsys):
    toml = _declared_log(tmp_path / "log", simulated_recording(4, MOTION), magnetometer=False)
    assert main(["broad", "--broad", toml, "--estimators", "mekf,triad", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "triad" in err and "magnetometer" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    assert main(["broad", "--broad", toml, "--magnetometer-sigma", "3", "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    assert ("--magnetometer-sigma = 3.0: needs a magnetometer, and these trials have none"
            in capsys.readouterr().err)


def test_a_log_without_an_accelerometer_is_refused_naming_it(tmp_path, capsys):
    recording = simulated_recording(5, MOTION)
    toml = _declared_log(tmp_path / "log", recording, magnetometer=False)
    text = open(toml).read()
    start = text.index("[recording.accelerometer]")
    stop = text.index("[recording.reference]")
    open(toml, "w").write(text[:start] + text[stop:])
    assert main(["broad", "--broad", toml, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "[recording.accelerometer]" in err and "replay" in err


def test_without_a_reference_six_axis_filters_are_ranked_by_their_inclinations(tmp_path,
                                                                               capsys):
    # No filter observes the heading, so their agreement is the inclination's:
    # each against the median of the others, every score said to be that.
    toml = _declared_log(tmp_path / "log", simulated_recording(3, MOTION), magnetometer=False,
                         reference=False)
    out = tmp_path / "out"
    assert main(["broad", "--broad", toml, "--estimators", "dead-reckoning,mekf,usque,mahony",
                 "--out", str(out), "--quiet"]) == 0
    table = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    assert (table["scored_against"] == "others' median").all()
    assert "each heading taken off" in capsys.readouterr().out
    assert table[["total_rmse_deg", "heading_rmse_deg"]].isna().all().all()
    agreement = table["inclination_rmse_deg"]
    assert np.isfinite(agreement).all()
    assert agreement["mekf"] < agreement["dead-reckoning"] / 2


@settings(max_examples=50, deadline=None)
@given(rotations=st.lists(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
                          min_size=2, max_size=2))
def test_taking_the_heading_off_keeps_every_inclination_error(rotations):
    # The agreement of 6-axis filters is taken on their attitudes without
    # their heading (each is its gyro's): the body's up is unchanged, so the
    # inclination error between any two is (1e-9°), and the heading is gone.
    a, b = (np.array([quat_from_rotvec(np.asarray(r))]) for r in rotations)
    before = errors_deg(a, b)["inclination"]
    level_a, level_b = without_heading(a), without_heading(b)
    assert abs(errors_deg(level_a, level_b)["inclination"][0] - before[0]) < 1e-9
    assert abs(level_a[0, 3]) < 1e-12 and abs(level_b[0, 3]) < 1e-12


def test_a_folder_mixing_six_and_nine_axis_logs_is_refused(tmp_path, capsys):
    # The ones are scored on their total error, the others on their
    # inclination: no group mean may mix them; each kind runs alone.
    recording = simulated_recording(3, MOTION)
    folder = tmp_path / "mixed"
    for name, magnetometer in (("a6", False), ("b9", True)):
        toml = _declared_log(tmp_path / name, recording, magnetometer)
        folder.mkdir(exist_ok=True)
        text = open(toml).read().replace('file = "log.csv"', f'file = "{name}.csv"')
        (folder / f"{name}.toml").write_text(text)
        (folder / f"{name}.csv").write_bytes((tmp_path / name / "log.csv").read_bytes())
    assert main(["broad", "--broad", str(folder), "--out", str(tmp_path / "out"),
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "without a magnetometer" in err and "a6" in err and len(err.splitlines()) == 1
    assert main(["broad", "--broad", str(folder), "--trials", "b9", "--estimators", "mekf",
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert main(["broad", "--broad", str(folder), "--case-study", "--trials", "a6",
                 "--out", str(tmp_path / "case"), "--quiet"]) == 2
    assert "have none" in capsys.readouterr().err


def test_samples_before_the_accelerometers_first_reading_are_left_out(tmp_path, capsys):
    # The accelerometer's own file begins 1 s after the gyro's, the body
    # tumbling from the first sample: the start attitude is taken at its
    # first reading, so the estimators start there, the second before it
    # left out and said (used at sample 0, the start was off by the body's
    # turn in that second: the MEKF's inclination 26° against 4.2° for the
    # same log read from the first sample).
    motion = HandheldMotion(rate_hz=100.0, rest_s=0.0, moving_s=30.0, final_rest_s=2.0,
                            taper_s=0.0)
    recording = simulated_recording(3, motion)
    toml = _declared_log(tmp_path / "log", recording, magnetometer=False)
    table = pd.read_csv(tmp_path / "log" / "log.csv")
    late = 100
    table.loc[:late - 1, ["ax", "ay", "az"]] = np.nan          # no reading yet
    table.to_csv(tmp_path / "log" / "log.csv", index=False)
    out = tmp_path / "out"
    assert main(["broad", "--broad", toml, "--estimators", "dead-reckoning,mekf", "--out",
                 str(out), "--quiet"]) == 0
    assert "its first 100 samples (1 s) come before" in capsys.readouterr().err
    scores = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    assert (scores["samples"] == recording.n_samples - late).all()
    assert scores.loc["mekf", "inclination_rmse_deg"] < 3.0
    assert scores.loc["dead-reckoning", "inclination_rmse_deg"] < 10.0


def test_an_npz_beside_declared_logs_is_named_where_it_is_left_out(tmp_path, capsys):
    # Without a trials.json a folder's [recording] .toml files are its trials:
    # an .npz beside them that none declares is left out, and said (it had
    # been left out without a word, the group of one trial scored).
    recording = simulated_recording(4, MOTION)
    _declared_log(tmp_path / "logs", recording, magnetometer=True)
    (tmp_path / "logs" / "other.npz").write_bytes(b"")
    assert main(["broad", "--broad", str(tmp_path / "logs"), "--estimators", "mekf",
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "left out other.npz: without a trials.json" in err
    assert 'declare one with file = "other.npz"' in err
