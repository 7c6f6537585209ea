"""The simulated hand-held IMU (dynamics/handheld.py, sensors/handheld.py):
its truth is the integral of its rates, its readings are that truth seen by
the sensors, bad settings are refused in one line, and the without-rest
script runs on it."""
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynamics.handheld import HandheldMotion, simulate_handheld
from dynamics.quaternion import quat_from_rotvec, quat_multiply, to_rotation
from dynamics.validation import InvalidParameterError
from sensors.handheld import GRAVITY_MPS2, HandheldImu, rate_before, simulated_recording

#: A short motion, so that each example takes milliseconds.
SHORT = HandheldMotion(rate_hz=50.0, rest_s=1.0, moving_s=4.0, final_rest_s=1.0, taper_s=0.5)
#: An IMU without errors: its readings are the truth seen by the sensors.
PERFECT = HandheldImu(gyro_bias_dps=0.0, gyro_scale_percent=0.0, gyro_misalignment_deg=0.0,
                      gyro_noise_density=0.0, accelerometer_sigma_mps2=0.0,
                      magnetometer_sigma_uT=0.0)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), rate_rms=st.floats(1.0, 400.0))
def test_the_attitude_is_the_rate_integrated_step_by_step(seed, rate_rms):
    motion = HandheldMotion(**{**SHORT.__dict__, "rate_rms_dps": rate_rms})
    truth = simulate_handheld(motion, np.random.default_rng(seed))
    q = truth.q_true[0]
    for k in range(1, len(truth.q_true)):
        q = quat_multiply(q, quat_from_rotvec(truth.omega_radps[k - 1] / motion.rate_hz))
        assert min(np.abs(q - truth.q_true[k]).max(), np.abs(q + truth.q_true[k]).max()) < 1e-9


def test_the_motion_rests_at_both_ends_and_moves_between():
    truth = simulate_handheld(SHORT, np.random.default_rng(1))
    rest, moving, final = SHORT.samples()
    assert truth.movement.tolist() == [False] * rest + [True] * moving + [False] * final
    still = ~truth.movement
    assert not truth.omega_radps[still].any() and not truth.acceleration_mps2[still].any()
    assert np.all(np.abs(truth.omega_radps[truth.movement]).max(axis=0) > 0)


def test_without_a_taper_each_axis_has_the_rms_asked_for():
    motion = HandheldMotion(**{**SHORT.__dict__, "taper_s": 0.0, "rate_rms_dps": 90.0,
                               "acceleration_rms_mps2": 3.0})
    truth = simulate_handheld(motion, np.random.default_rng(2))
    moving = truth.movement
    np.testing.assert_allclose(np.degrees(truth.omega_radps[moving]).std(axis=0), 90.0,
                               rtol=1e-12)
    np.testing.assert_allclose(truth.acceleration_mps2[moving].std(axis=0), 3.0, rtol=1e-12)


def test_the_taper_ramps_the_motion_in_and_out():
    """Over the taper's 25 samples the rate grows as k/25 of the untapered
    noise: its first samples are small beside the movement's RMS."""
    truth = simulate_handheld(SHORT, np.random.default_rng(2))
    rest, moving, _ = SHORT.samples()
    rms = np.radians(SHORT.rate_rms_dps)
    edges = np.abs(truth.omega_radps[[rest, rest + moving - 1]])
    assert not edges.any()
    assert np.abs(truth.omega_radps[rest + 1]).max() < 5 * rms / 25


def test_a_perfect_imu_reads_the_truth():
    recording = simulated_recording(3, SHORT, PERFECT)
    truth = simulate_handheld(SHORT, np.random.default_rng(3))
    np.testing.assert_array_equal(recording.reference_quat, truth.q_true)
    np.testing.assert_allclose(recording.gyro_radps, rate_before(truth.omega_radps), atol=1e-15)
    # ...which is the rotation between each sample and the one before it,
    # over its interval, read off the truth's attitudes themselves.
    attitudes = to_rotation(truth.q_true)
    turned = (attitudes[:-1].inv() * attitudes[1:]).as_rotvec() * recording.rate_hz
    np.testing.assert_allclose(recording.gyro_radps[1:], turned, atol=1e-9)
    to_world = to_rotation(recording.reference_quat)
    np.testing.assert_allclose(to_world.apply(recording.magnetometer_uT),
                               np.tile(PERFECT.field_world(), (len(truth.q_true), 1)), atol=1e-9)
    force = to_world.apply(recording.accelerometer_mps2)   # at rest, gravity reads up
    np.testing.assert_allclose(force, truth.acceleration_mps2 + [0.0, 0.0, GRAVITY_MPS2],
                               atol=1e-9)
    field = PERFECT.field_world()
    assert np.linalg.norm(field) == pytest.approx(49.0)
    assert np.degrees(np.arctan2(-field[2], field[1])) == pytest.approx(66.0)


def test_the_gyro_reads_the_interval_before_each_sample_as_the_filters_take_it():
    # Integrated as the filters integrate an IMU's gyro (rate_interpolation
    # "end": reading k turns the body from sample k-1 to k), the perfect
    # IMU's readings give the truth back; taken as the interval after each
    # sample they are a sample late, off by the turn of a step.
    recording = simulated_recording(6, SHORT, PERFECT)
    truth, dt = recording.reference_quat, recording.dt
    q = truth[0]
    for k in range(1, len(truth)):
        q = quat_multiply(q, quat_from_rotvec(recording.gyro_radps[k] * dt))
        assert min(np.abs(q - truth[k]).max(), np.abs(q + truth[k]).max()) < 1e-9
    late, worst = truth[0], 0.0
    for k in range(1, len(truth)):
        late = quat_multiply(late, quat_from_rotvec(recording.gyro_radps[k - 1] * dt))
        worst = max(worst, min(np.abs(late - truth[k]).max(), np.abs(late + truth[k]).max()))
    assert worst > 1e-3


def test_the_gyro_bias_is_constant_and_within_its_bound():
    imu = HandheldImu(gyro_bias_dps=2.0, gyro_scale_percent=0.0, gyro_misalignment_deg=0.0,
                      gyro_noise_density=0.0)
    recording = simulated_recording(4, SHORT, imu)
    truth = simulate_handheld(SHORT, np.random.default_rng(4))
    offset = np.degrees(recording.gyro_radps - rate_before(truth.omega_radps))
    np.testing.assert_allclose(offset, np.tile(offset[0], (len(offset), 1)), atol=1e-12)
    assert np.all(np.abs(offset[0]) <= 2.0) and np.any(offset[0] != 0.0)


@pytest.mark.parametrize("make, shown", [
    (lambda: HandheldMotion(rate_hz=0.0), "rate_hz = 0.0: must be > 0"),
    (lambda: HandheldMotion(moving_s=-1.0), "moving_s = -1.0: must be > 0"),
    (lambda: HandheldMotion(rest_s=float("nan")), "rest_s = nan: must be finite"),
    (lambda: HandheldMotion(bandwidth_hz=150.0), "bandwidth_hz = 150.0: must be below half"),
    (lambda: HandheldMotion(moving_s=4.0, taper_s=3.0), "taper_s = 3.0: must be at most half"),
    (lambda: HandheldImu(dip_deg=100.0), "dip_deg = 100.0: must be within ±90°"),
    (lambda: HandheldImu(field_uT=0.0), "field_uT = 0.0: must be > 0"),
    (lambda: HandheldImu(gyro_bias_dps=-1.0), "gyro_bias_dps = -1.0"),
    (lambda: HandheldImu(gyro_scale_percent=float("inf")), "gyro_scale_percent = inf"),
])
def test_a_bad_setting_is_refused_in_one_line(make, shown):
    with pytest.raises(InvalidParameterError) as refused:
        make()
    assert str(refused.value).startswith(shown) and "\n" not in str(refused.value)


def test_the_without_rest_script_runs_on_simulated_recordings(tmp_path, capsys):
    from benchmarks.broad import without_rest
    assert without_rest.main(["--simulated", "1", "--estimators", "mekf", "--quiet",
                              "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "without_rest.csv")
    assert table[["trial", "estimator"]].values.tolist() == [["handheld-0", "mekf"]]
    assert table["cut_at_sample"].tolist() == [HandheldMotion().samples()[0]]   # 10 s at 200 Hz
    assert np.all(np.isfinite(table[["whole_deg", "without_rest_deg"]].to_numpy()))
    assert "1 simulated hand-held recordings" in capsys.readouterr().out
    assert "Simulated" in (tmp_path / "ATTRIBUTION.txt").read_text()


def test_the_simulated_recordings_take_the_motion_and_imu_asked_for(tmp_path, capsys):
    # Each FIELD=VALUE reaches the simulation: the table is the one made by
    # hand from the same motion and IMU (a shorter rest moves the cut too).
    from benchmarks.broad import without_rest
    assert without_rest.main(["--simulated", "1", "--estimators", "mekf", "--quiet",
                              "--motion", "rest_s=5", "--motion", "moving_s=20",
                              "--motion", "final_rest_s=2", "--imu", "gyro_scale_percent=0",
                              "--out", str(tmp_path)]) == 0
    motion = HandheldMotion(rest_s=5.0, moving_s=20.0, final_rest_s=2.0)
    expected = without_rest.recording_scores(
        simulated_recording(0, motion, HandheldImu(gyro_scale_percent=0.0)), "handheld-0",
        ["mekf"])
    table = pd.read_csv(tmp_path / "without_rest.csv")
    assert table["cut_at_sample"].tolist() == [1000]          # 5 s at 200 Hz
    for column in ("whole_deg", "without_rest_deg"):
        assert table[column].tolist() == [row[column] for row in expected]
    assert "(rest_s=5, moving_s=20, final_rest_s=2, gyro_scale_percent=0)" in \
        capsys.readouterr().out


@pytest.mark.parametrize("argv, shown", [
    (["--simulated", "0"], "--simulated = 0: must be a whole number >= 1"),
    (["--simulated", "1", "--motion", "rate=3"], "--motion = 'rate=3': must be FIELD=NUMBER "
                                                 "with FIELD one of rate_hz, rest_s"),
    (["--simulated", "1", "--imu", "dip_deg=north"], "--imu = 'dip_deg=north': must be "
                                                     "FIELD=NUMBER"),
    (["--simulated", "1", "--imu", "dip_deg=95"], "dip_deg = 95.0: must be within ±90°"),
    (["--motion", "rate_rms_dps=250"], "--motion = 'rate_rms_dps=250': applies to "
                                       "--simulated only"),
    (["--simulated", "1", "--broad", "x"], "--simulated = 1: cannot be given with --broad"),
    (["--simulated", "1", "--estimators", "nope"], "estimator = 'nope'"),
])
def test_the_without_rest_script_refuses_bad_simulations_in_one_line(argv, shown, tmp_path,
                                                                     capsys):
    from benchmarks.broad import without_rest
    assert without_rest.main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"without_rest: error: {shown}") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_the_gyro_reads_the_rate_through_its_scale_and_misalignment():
    """Without bias and noise the gyro is (I + M) ω: M's diagonal within the
    scale bound, its other entries within the misalignment's, found back by
    least squares from the readings to the exact rates."""
    imu = HandheldImu(gyro_bias_dps=0.0, gyro_noise_density=0.0, gyro_scale_percent=2.0,
                      gyro_misalignment_deg=1.0)
    recording = simulated_recording(5, SHORT, imu)
    truth = simulate_handheld(SHORT, np.random.default_rng(5))
    rates = rate_before(truth.omega_radps)
    matrix = np.linalg.lstsq(rates, recording.gyro_radps, rcond=None)[0].T
    errors = matrix - np.eye(3)
    assert np.all(np.abs(np.diag(errors)) <= 0.02) and np.any(np.diag(errors) != 0.0)
    off = errors[~np.eye(3, dtype=bool)]
    assert np.all(np.abs(off) <= np.radians(1.0)) and np.any(off != 0.0)
    np.testing.assert_allclose(recording.gyro_radps, rates @ matrix.T, atol=1e-12)


@pytest.mark.parametrize("inputs", ["broad", "replay"])
def test_dead_reckoning_takes_a_recorded_gyro_as_an_imus(inputs):
    """broad's and replay's scenarios take each gyro sample as the rate over
    the interval before it (RECORDED_GYRO): dead reckoning on a perfect IMU
    then follows the truth but for its first-order step's error, where
    holding each sample over the interval after lagged by a step's turn
    (about 0.5° at 100 °/s and 200 Hz)."""
    from benchmarks.broad.inputs import imu_inputs
    from benchmarks.broad.metric import errors_deg
    from benchmarks.engine.recorded import run_recorded
    from benchmarks.experiments.replay import replay_scenario
    from estimators import resolve_estimator
    motion = HandheldMotion(rate_hz=200.0, rest_s=0.5, moving_s=10.0, final_rest_s=0.5,
                            rate_rms_dps=100.0)
    recording = simulated_recording(1, motion, PERFECT)
    scenario = (imu_inputs(recording).scenario if inputs == "broad"
                else replay_scenario(recording))
    worst = {}
    for timing in (None, "step-average"):
        options = {} if timing is None else {"rate_timing": timing}
        estimator = resolve_estimator("dead-reckoning").from_scenario(scenario, **options)
        assert timing or estimator.rate_timing == "end"
        estimator.initial_attitude = recording.reference_quat[0]
        run = run_recorded(estimator, recording.gyro_radps)
        worst[timing] = errors_deg(run.estimates, recording.reference_quat)["total"].max()
    assert worst[None] < 0.02 and worst["step-average"] > 0.3
    for name in ("mekf", "usque", "ekf", "dead-reckoning-resets"):
        estimator = resolve_estimator(name).from_scenario(scenario)
        assert getattr(estimator, "rate_interpolation", getattr(estimator, "rate_timing", None)) \
            == "end"


def test_the_ekf_takes_an_imus_reading_as_the_rate_over_the_step_before_it():
    """On a perfect IMU's gyro alone (no reading: a recording's kernel path
    has none; the update's order is held to the class by the engine's
    property test), the additive EKF that takes each reading over the step
    before it, as a recording's scenario sets it, is the truth to its
    first-order step; held over the step after, it lags by a step's turn.
    The kernel and the per-run class give the same numbers."""
    from benchmarks.broad.metric import errors_deg
    from benchmarks.engine.recorded import run_recorded
    from benchmarks.experiments.replay import replay_scenario
    from estimators import resolve_estimator
    motion = HandheldMotion(rate_hz=200.0, rest_s=0.5, moving_s=5.0, final_rest_s=0.5,
                            rate_rms_dps=100.0)
    recording = simulated_recording(2, motion, PERFECT)
    scenario = replay_scenario(recording, interval_s=1.0, noise_deg=1e-3)
    errors = {}
    for interpolation in ("end", "hold"):
        ekf = resolve_estimator("ekf").from_scenario(scenario, rate_interpolation=interpolation)
        kernel = run_recorded(ekf, recording.gyro_radps).estimates
        per_run = ekf.run(recording.gyro_radps, recording.reference_quat,
                          np.zeros(recording.n_samples, bool))
        np.testing.assert_allclose(kernel, per_run, rtol=0, atol=1e-9)
        errors[interpolation] = errors_deg(kernel, recording.reference_quat)["total"].max()
    assert errors["end"] < 0.02 < 0.3 < errors["hold"]


@pytest.mark.parametrize("name", ["madgwick", "mahony"])
def test_the_complementary_filters_leave_out_the_rate_before_a_recordings_start(name):
    """Started from the true attitude at a sample of a perfect IMU turning
    about 300 °/s, Madgwick's and Mahony's first estimate integrates the
    rate before that sample unless told, as a recording's scenario tells
    them (RECORDED_GYRO), that the start is the attitude at it; their
    compiled loops give the class's numbers."""
    from benchmarks.broad.inputs import imu_inputs
    from benchmarks.broad.metric import errors_deg
    from benchmarks.engine.recorded import run_recorded
    from estimators import resolve_estimator
    motion = HandheldMotion(rate_hz=200.0, rest_s=0.5, moving_s=10.0, final_rest_s=0.5,
                            rate_rms_dps=300.0)
    recording = simulated_recording(1, motion, PERFECT)
    start = int(np.argmax(np.linalg.norm(recording.gyro_radps, axis=1) > np.radians(200.0)))
    part = recording.from_sample(start)
    inputs = imu_inputs(part)
    first = {}

    def make(options):
        return resolve_estimator(name).from_scenario(
            inputs.scenario, initial_attitude=part.reference_quat[0], **options)

    for options in ({}, {"rate_timing": "workshop"}):
        assert make(options).rate_timing == options.get("rate_timing", "end")
        compiled = run_recorded(make(options), inputs.sensors.omega_meas_radps, inputs.sensors.vectors)
        assert compiled.path == "compiled"
        per_run = make(options).run(inputs.sensors.omega_meas_radps, part.reference_quat,
                             np.zeros(part.n_samples, bool), vectors=inputs.sensors.vectors)
        np.testing.assert_allclose(compiled.estimates, per_run, rtol=0, atol=1e-12)
        first[options.get("rate_timing", "end")] = errors_deg(
            compiled.estimates[:1], part.reference_quat[:1])["total"][0]
    assert first["end"] < 0.1 < 0.5 < first["workshop"]


@pytest.mark.parametrize("name", ["madgwick", "mahony"])
@pytest.mark.parametrize("timing", ["workshop", "end"])
def test_the_compiled_complementary_loops_keep_to_their_class_at_the_edges(name, timing):
    """Without any vector reading (the gyro integrated alone) the compiled
    loop is its class to 1e-12 (its readings' arrays had been empty, read
    past their end); a first gyro reading that is not finite is a divergence
    at step 0 with either timing (leaving rate 0 out had hidden it)."""
    from benchmarks.engine.recorded import run_recorded
    from estimators import resolve_estimator
    motion = HandheldMotion(rate_hz=100.0, rest_s=0.5, moving_s=4.0, final_rest_s=0.5)
    recording = simulated_recording(5, motion, PERFECT)
    n = recording.n_samples

    def make():
        return resolve_estimator(name)(dt=recording.dt, rate_timing=timing,
                                       initial_attitude=recording.reference_quat[0])
    compiled = run_recorded(make(), recording.gyro_radps)
    assert compiled.path == "compiled"
    per_run = make().run(recording.gyro_radps, recording.reference_quat, np.zeros(n, bool))
    np.testing.assert_allclose(compiled.estimates, per_run, rtol=0, atol=1e-12)
    broken = recording.gyro_radps.copy()
    broken[0, 1] = np.nan
    assert run_recorded(make(), broken).diverged_step == 0
