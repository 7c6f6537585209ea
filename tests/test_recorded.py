"""Recorded readings through the engine (:mod:`benchmarks.engine.recorded`):
every fast path (a Monte Carlo kernel, the compiled complementary filters,
the batch calls of the peers and of TRIAD) against the per-run class, to
1e-9 at every sample, with the same gating counts; and the fallbacks.

The data are a slice of the shipped BROAD trial 07 (fast rotation) from the
start of its movement, where the MEKF's gate rejects most accelerometer
readings: the counts are compared, not only the estimates.
"""
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from benchmarks.broad.dataset import open_broad
from benchmarks.broad.inputs import imu_inputs
from benchmarks.engine.recorded import _finished, field_timed, path_of, run_recorded
from benchmarks.shipped import shipped_file
from benchmarks.simulation import build_estimator
from estimators import AttitudeEstimator, resolve_estimator, triad, wahba
from estimators.readings import InvalidMeasurementError

#: The slice: from the start of trial 07's movement (sample 7573), long
#: enough for the gate to act, short enough for the per-run USQUE.
START, LENGTH = 7500, 1500


@pytest.fixture(scope="module")
def trial():
    dataset = open_broad(shipped_file("datasets/broad/trials.json").parent)
    inputs = imu_inputs(dataset.load("07_undisturbed_fast_rotation_B"))
    part = slice(START, START + LENGTH)
    vectors = tuple(v.steps(part) for v in inputs.sensors.vectors)
    return inputs.scenario, inputs.sensors.omega_meas_radps[part], vectors


def _per_run(estimator, omega, vectors):
    n = len(omega)
    estimates = estimator.run(omega, np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros(n, bool),
                              vectors=vectors)
    return estimates, dict(estimator.rejected)


@pytest.mark.parametrize("name, path", [
    ("dead-reckoning", "kernel"), ("mekf", "kernel"),
    pytest.param("usque", "kernel", marks=pytest.mark.slow),       # 3 s
    ("mekf-smoother", "kernel"),
    ("madgwick", "compiled"), ("madgwick-broad", "compiled"), ("mahony", "compiled"),
    ("triad", "batch"), ("vqf", "batch"), ("vqf-6d", "batch"), ("fusion", "batch")])
def test_each_fast_path_gives_the_per_run_estimates_and_rejections(trial, name, path):
    if name in ("vqf", "vqf-6d"):
        pytest.importorskip("vqf")
    if name == "fusion":
        pytest.importorskip("imufusion")
    scenario, omega, vectors = trial
    # the readings as the estimator reads them (an offline one times its field)
    per_run = build_estimator(name, scenario)
    reference, rejected = _per_run(per_run, omega, field_timed(per_run, omega, vectors)[0])
    # A used object: the fast path resets it first, as run does.
    estimator = build_estimator(name, scenario)
    estimator.run(omega[:10], np.tile([1.0, 0, 0, 0], (10, 1)), np.zeros(10, bool),
                  vectors=[v.steps(slice(10)) for v in vectors])
    run = run_recorded(estimator, omega, vectors)
    assert run.path == path
    # Sign-aligned: q and -q are one attitude, and every path keeps the sign its class keeps.
    np.testing.assert_allclose(run.estimates, reference, rtol=0, atol=1e-9)
    assert run.rejected == rejected
    assert run.diverged_step is None


def _textbook(scenario, name="mekf", **options):
    """``scenario`` with ``name``'s IMU models off: acc/mag as vector readings."""
    textbook = {"gravity_model": "reading", "magnetometer_model": "vector",
                "rest_updates": False, "hard_iron_fit": False, "gate_probability": 0.9999}
    merged = dict(scenario.estimator_options)
    merged[name] = {**merged.get(name, {}), **textbook, **options}
    return scenario.replace(estimator_options=merged)


def test_the_mekf_gate_is_counted_on_the_kernel_path(trial):
    scenario, omega, vectors = trial
    textbook = _textbook(scenario)
    reference, rejected = _per_run(build_estimator("mekf", textbook), omega, vectors)
    run = run_recorded(build_estimator("mekf", textbook), omega, vectors)
    np.testing.assert_allclose(run.estimates, reference, rtol=0, atol=1e-9)
    assert run.rejected == rejected
    # Fast rotation: the centripetal acceleration fails the gate (not a vacuous count).
    assert run.rejected.get("accelerometer", 0) > LENGTH // 10


def test_without_the_magnetometer_triad_falls_back_and_vqf_runs_at_once(trial):
    # TRIAD has no batch path without two directions; VQF's batch call is
    # fed no field (a 6-axis IMU), as its per-run class is.
    scenario, omega, vectors = trial
    gravity_only = vectors[:1]
    for name, path in (("triad", "per-run"), ("vqf", "batch")):
        if name == "vqf":
            pytest.importorskip("vqf")
        estimator = build_estimator(name, scenario)
        run = run_recorded(estimator, omega, gravity_only)
        assert run.path == path
        reference, _ = _per_run(build_estimator(name, scenario), omega, gravity_only)
        np.testing.assert_allclose(run.estimates, reference, rtol=0.0, atol=1e-9)


def test_an_estimator_of_a_users_own_takes_the_per_run_path(trial):
    class Still(AttitudeEstimator):
        name = "still"

        def reset(self):
            pass

        def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()):
            return self.initial_attitude.copy()

        @property
        def attitude(self):
            return self.initial_attitude.copy()

    scenario, omega, vectors = trial
    estimator = Still(dt=scenario.dt, initial_attitude=np.array([1.0, 0.0, 0.0, 0.0]))
    assert path_of(estimator, vectors) == "per-run"
    assert np.all(run_recorded(estimator, omega, vectors).estimates[:, 0] == 1.0)


def test_a_fast_paths_estimates_are_nan_from_the_first_sample_not_finite():
    estimates = np.tile([1.0, 0.0, 0.0, 0.0], (6, 1))
    estimates[3, 2] = np.inf
    run = _finished(estimates, "compiled")
    assert run.diverged_step == 3
    assert np.isnan(run.estimates[3:]).all() and np.isfinite(run.estimates[:3]).all()


unit = st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3).map(np.array) \
    .filter(lambda v: np.linalg.norm(v) > 0.1).map(lambda v: v / np.linalg.norm(v))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(unit, unit, unit, unit), min_size=1, max_size=5))
def test_triad_on_stacked_pairs_is_triad_on_each(pairs):
    pairs = [p for p in pairs if all(np.linalg.norm(np.cross(a, b)) > 0.05
                                     for a, b in ((p[0], p[1]), (p[2], p[3])))]
    assume(pairs)           # an example with no usable pair is drawn again, not passed
    b1, b2, r1, r2 = (np.array(column) for column in zip(*pairs))
    stacked = triad.triad_attitudes(b1, b2, r1, r2)
    for k, (u, v, x, y) in enumerate(pairs):
        one = wahba.triad(np.array([u, v]), np.array([x, y]), np.array([2.0, 1.0]))
        np.testing.assert_allclose(stacked[k], one, rtol=0, atol=1e-12)


def test_triads_batch_anchors_on_the_heavier_reading_as_solve_does(trial):
    scenario, omega, vectors = trial
    heavy_field = scenario.replace(estimator_options={"triad": {"magnetometer_weight": 1e3}})
    part = [v.steps(slice(300)) for v in vectors]
    reference, _ = _per_run(build_estimator("triad", heavy_field), omega[:300], part)
    run = run_recorded(build_estimator("triad", heavy_field), omega[:300], part)
    light = run_recorded(build_estimator("triad", scenario), omega[:300], part)
    np.testing.assert_allclose(run.estimates, reference, rtol=0, atol=1e-12)
    # The anchor matters: gravity first and the field first are different solutions.
    assert np.max(np.abs(run.estimates - light.estimates)) > 1e-3


@pytest.mark.parametrize("name", [
    "mekf", pytest.param("usque", marks=pytest.mark.slow)])  # USQUE per-run twice: 6 s
def test_a_disturbed_field_is_rejected_by_its_magnitude_on_both_paths(trial, name):
    scenario, omega, vectors = trial
    accelerometer, magnetometer = vectors
    body = magnetometer.body.copy()
    body[400:700] *= 1.3            # a magnet nearby: the field 30 % stronger
    disturbed = (accelerometer, replace(magnetometer, body=body))
    tested = _textbook(scenario, name, magnetic_norm_tolerance=0.1)
    options = dict(tested.estimator_options)
    reference, rejected = _per_run(build_estimator(name, tested), omega, disturbed)
    run = run_recorded(build_estimator(name, tested), omega, disturbed)
    np.testing.assert_allclose(run.estimates, reference, rtol=0, atol=1e-9)
    assert run.rejected == rejected
    assert rejected["magnetometer"] >= 300          # every disturbed reading, at least
    options[name]["magnetic_norm_tolerance"] = None
    _, untested = _per_run(build_estimator(name, scenario.replace(estimator_options=options)),
                           omega, disturbed)
    assert untested.get("magnetometer", 0) < 300    # the χ² gate alone lets some through


def _turned(vectors, declination_deg: float):
    """The readings with the field's reference turned ``declination_deg`` east
    of north (the body readings as they were): a site with a declination."""
    angle = np.radians(declination_deg)
    turn = np.array([[np.cos(angle), np.sin(angle), 0.0],
                     [-np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    return tuple(replace(v, reference=v.reference @ turn) if v.sensor == "magnetometer" else v
                 for v in vectors)


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf", "fusion"])
def test_a_declination_turns_the_estimate_alike_on_every_path(trial, name):
    """The magnetic-frame filters are turned by the declination of the field's
    reference (so that they are scored against the north they estimate), on
    the fast path as on the per-run path; with no declination nothing turns."""
    if name == "vqf":
        pytest.importorskip("vqf")
    if name == "fusion":
        pytest.importorskip("imufusion")
    scenario, omega, vectors = trial
    turned = _turned(vectors, 4.0)
    assert turned[1].reference[0, 0] != 0.0
    reference, _ = _per_run(build_estimator(name, scenario), omega, turned)
    run = run_recorded(build_estimator(name, scenario), omega, turned)
    assert run.path != "per-run"
    assert np.abs(run.estimates - reference).max() < 1e-9
    plain, _ = _per_run(build_estimator(name, scenario), omega, vectors)
    angles = np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(plain * reference, axis=1)), 0, 1)))
    if name in ("vqf", "fusion"):
        # They start themselves from the readings: the turn is 4° about the
        # vertical at every sample (to Fusion's single precision).
        assert np.allclose(angles, 4.0, atol=1e-6 if name == "vqf" else 1e-3)
    else:
        # Started where they were told, in the turned frame: the estimate goes
        # on from there (no jump at the first sample) and moves toward the turn.
        assert angles[0] < 0.2 and 1.0 < angles[-1] < 4.0


@pytest.mark.parametrize("name", ["mekf", pytest.param("usque", marks=pytest.mark.slow)])
def test_the_kernels_innovation_likelihood_is_the_per_run_filters(trial, name):
    # The tuner without a reference (broad --tune halves) reads these sums:
    # both paths give the same ln det S + NIS over the same updates.
    scenario, omega, vectors = trial
    kernel_run = run_recorded(build_estimator(name, scenario), omega, vectors, innovations=True)
    per_run = build_estimator(name, scenario)
    per_run.log_innovations = True
    _per_run(per_run, omega, vectors)
    sums = per_run.innovation_sums
    assert kernel_run.path == "kernel" and kernel_run.likelihood[1] == sums["updates"] > 100
    assert kernel_run.likelihood[0] == pytest.approx(sums["log_det"] + sums["nis"], rel=1e-9)
    assert run_recorded(build_estimator(name, scenario), omega, vectors).likelihood is None


@pytest.mark.parametrize("name", ["mekf", pytest.param("usque", marks=pytest.mark.slow)])
@pytest.mark.parametrize("models", [{}, {"gravity_model": "reading", "magnetometer_model":
                                         "vector", "hard_iron_fit": False}],
                         ids=["imu-models", "vector-updates"])
def test_the_kernels_likelihood_counts_rejected_readings_as_the_per_run_filters(trial, name,
                                                                                models):
    # A tight gate (p = 0.5) rejects readings on each path through the
    # updates (the IMU models' gravity and heading, the plain vector
    # update): both paths count each at the gate's threshold.
    scenario, omega, vectors = trial
    options = {"gate_probability": 0.5, **models}
    from estimators import resolve_estimator
    kernel_run = run_recorded(resolve_estimator(name).from_scenario(scenario, **options), omega,
                              vectors, innovations=True)
    per_run = resolve_estimator(name).from_scenario(scenario, **options)
    per_run.log_innovations = True
    _, rejected = _per_run(per_run, omega, vectors)
    sums = per_run.innovation_sums
    assert sum(rejected.values()) > 20, rejected
    assert kernel_run.path == "kernel" and kernel_run.likelihood[1] == sums["updates"]
    assert kernel_run.likelihood[0] == pytest.approx(sums["log_det"] + sums["nis"], rel=1e-9)


@pytest.mark.parametrize("name", ["mekf", "usque", "mekf-smoother"])
def test_the_kept_attitude_covariance_is_the_per_run_classs(trial, name):
    """The covariance the kernel path keeps (and the smoother's fusion of
    its passes) is the per-run class's ``track`` covariance, to 1e-9 of its
    scale at every sample: the tables' claimed heading and inclination
    (:func:`benchmarks.broad.metric.claimed_deg`) read the filter's own."""
    scenario, omega, vectors = trial
    n = 600             # long enough for the gate and the models to act
    omega, vectors = omega[:n], tuple(v.steps(slice(n)) for v in vectors)
    trace = build_estimator(name, scenario).track(omega, np.tile([1.0, 0, 0, 0], (n, 1)),
                                                  np.zeros(n, bool), vectors=vectors)
    run = run_recorded(build_estimator(name, scenario), omega, vectors)
    assert run.attitude_covariance.shape == (n, 3, 3)
    scale = np.abs(trace.attitude_covariance).max()
    np.testing.assert_allclose(run.attitude_covariance, trace.attitude_covariance, rtol=0,
                               atol=1e-9 * scale)


def test_a_path_that_keeps_no_covariance_says_none(trial):
    scenario, omega, vectors = trial
    for name in ("madgwick", "triad", "dead-reckoning"):
        assert run_recorded(build_estimator(name, scenario), omega,
                            vectors).attitude_covariance is None


def test_the_per_run_path_keeps_the_covariance_its_class_tracks(trial):
    """The EKF takes the per-run path on IMU readings (its kernel has no
    vector updates): its covariance is still kept, its class's own, and its
    estimates are those of ``run``."""
    scenario, omega, vectors = trial
    n = 300
    omega, vectors = omega[:n], tuple(v.steps(slice(n)) for v in vectors)
    run = run_recorded(build_estimator("ekf", scenario), omega, vectors)
    assert run.path == "per-run"
    reference, _ = _per_run(build_estimator("ekf", scenario), omega, vectors)
    np.testing.assert_array_equal(run.estimates, reference)
    trace = build_estimator("ekf", scenario).track(omega, np.tile([1.0, 0, 0, 0], (n, 1)),
                                                   np.zeros(n, bool), vectors=vectors)
    np.testing.assert_array_equal(run.attitude_covariance, trace.attitude_covariance)
    assert run.attitude_covariance.shape == (n, 3, 3)


def test_a_whole_records_own_methods_refuse_its_rates_by_the_same_rule(trial):
    # Offline VQF's run_batch, run_recorded and a per-run class's run (the
    # smoother's too) read the rates by one rule (estimators.readings.checked_rates):
    # a column of rates was an AxisError inside run_batch; complex rates lost
    # their imaginary part (with a ComplexWarning) in run_recorded, run_batch
    # and the smoother's run.
    pytest.importorskip("vqf")
    scenario, omega, vectors = trial
    n = len(omega)
    offline = resolve_estimator("vqf-offline").from_scenario(scenario)
    with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps of shape = \(1500,\): "
                                                      r"must have shape \(N, 3\)"):
        offline.run_batch(omega[:, 0], vectors)
    complex_rates = omega.astype(complex)
    for name in ("mekf", "mekf-smoother", "vqf-offline"):
        estimator = resolve_estimator(name).from_scenario(scenario)
        with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps = .*must be real"):
            run_recorded(estimator, complex_rates, vectors)
        if name != "vqf-offline":
            with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps = .*real"):
                estimator.run(complex_rates, np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros(n, bool))
    with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps = .*must be real"):
        offline.run_batch(complex_rates, vectors)
    bad = omega.copy()
    bad[7, 1] = np.nan
    with pytest.raises(InvalidMeasurementError, match=r"^omega_meas_radps at step 7 = .*finite"):
        offline.run_batch(bad, vectors)


@pytest.mark.parametrize("name", ["mekf", "mekf-smoother", "vqf-offline", "madgwick", "triad"])
def test_a_malformed_record_is_refused_in_one_rule_on_every_path(trial, name):
    # Checked before any path reads it (the offline estimators' field
    # timing, a kernel's arrays): the per-run classes' own rules, not an
    # IndexError from deep inside
    scenario, omega, vectors = trial
    estimator = resolve_estimator(name).from_scenario(scenario)
    with pytest.raises(InvalidMeasurementError, match=r"omega_meas_radps of shape = \(1500,\)"):
        run_recorded(estimator, omega[:, 0], vectors)
    short = tuple(replace(v, body=v.body[:-1]) if v.sensor == "magnetometer" else v
                  for v in vectors)
    with pytest.raises(InvalidMeasurementError,
                       match=r"vectors\[magnetometer\]\.body of shape = \(1499, 3\): must have "
                             r"shape \(1500, 3\)"):
        run_recorded(estimator, omega, short)
