"""Property-based tests (hypothesis): invariants that hold for all inputs."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.scenario import Scenario, flatten_sections
from dynamics.quaternion import (
    attitude_error_rad,
    from_rotation,
    grp_from_quat,
    quat_conjugate,
    quat_from_grp,
    quat_from_rotvec,
    quat_multiply,
    rotvec_from_quat,
    to_rotation,
)
from dynamics.validation import InvalidParameterError
from estimators.mekf import discrete_error_model
from estimators.model import propagate_with_jacobian

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vectors4 = st.lists(finite, min_size=4, max_size=4).filter(
    lambda v: np.linalg.norm(v) > 1e-3)
unit_quaternions = vectors4.map(lambda v: np.asarray(v) / np.linalg.norm(v))
rotation_vectors = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3).map(
    np.asarray).filter(lambda v: np.linalg.norm(v) < np.pi - 1e-3)   # the log's own range


@given(unit_quaternions, unit_quaternions, unit_quaternions)
def test_product_is_associative_and_keeps_the_norm(a, b, c):
    left = quat_multiply(quat_multiply(a, b), c)
    right = quat_multiply(a, quat_multiply(b, c))
    assert np.allclose(left, right, atol=1e-14)
    assert abs(np.linalg.norm(left) - 1) < 1e-14


@given(unit_quaternions)
def test_conjugate_is_the_inverse_and_scipy_round_trips(q):
    assert np.allclose(quat_multiply(q, quat_conjugate(q)), [1, 0, 0, 0], atol=1e-15)
    back = from_rotation(to_rotation(q))
    assert attitude_error_rad(q, back) < 1e-7        # the metric's own floor
    assert np.allclose(np.abs(back @ q), 1.0, atol=1e-14)


@given(unit_quaternions, unit_quaternions)
def test_error_is_sign_invariant_and_symmetric(a, b):
    e = attitude_error_rad(a, b)
    assert e == attitude_error_rad(-a, b) == attitude_error_rad(a, -b)
    assert abs(e - attitude_error_rad(b, a)) < 1e-15
    assert 0 <= e <= np.pi + 1e-12


@given(rotation_vectors)
def test_rotation_vector_and_grp_round_trip(theta):
    q = quat_from_rotvec(theta)
    assert np.allclose(rotvec_from_quat(q), theta, atol=1e-12)
    assert np.allclose(quat_from_grp(grp_from_quat(q)), q * np.sign(q[0] or 1.0), atol=1e-12)


@settings(max_examples=60)
@given(unit_quaternions, st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
       st.sampled_from([0.001, 0.01, 0.1]))
def test_workshop_jacobian_matches_central_differences(q, omega, dt):
    omega = np.asarray(omega)
    _, jacobian = propagate_with_jacobian(q, omega, dt)
    step = 1e-6
    numeric = np.column_stack([
        (propagate_with_jacobian(q + step * e, omega, dt)[0]
         - propagate_with_jacobian(q - step * e, omega, dt)[0]) / (2 * step) for e in np.eye(4)])
    assert np.allclose(numeric, jacobian, atol=1e-8)


@settings(max_examples=60)
@given(unit_quaternions, st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
       st.lists(st.floats(-1e-2, 1e-2), min_size=3, max_size=3))
def test_mekf_transition_matches_finite_differences_of_the_kinematics(q_hat, omega, beta):
    # Φ against central differences of the noise-free error propagation, at random states.
    dt = 0.1
    omega, beta = np.asarray(omega), np.asarray(beta)
    phi, _ = discrete_error_model(omega - beta, dt, 0.0, 0.0)
    centre = quat_multiply(q_hat, quat_from_rotvec((omega - beta) * dt))

    def error_after(delta):
        q = quat_multiply(quat_multiply(q_hat, quat_from_rotvec(delta[:3])),
                          quat_from_rotvec((omega - beta - delta[3:]) * dt))
        return np.concatenate([rotvec_from_quat(quat_multiply(quat_conjugate(centre), q)),
                               delta[3:]])

    step = 1e-6
    numeric = np.column_stack([(error_after(step * e) - error_after(-step * e)) / (2 * step)
                               for e in np.eye(6)])
    assert np.allclose(numeric, phi, atol=1e-7)


@settings(max_examples=80)
@given(st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3), st.floats(1e-4, 0.1),
       st.one_of(st.just(0.0), st.floats(1e-9, 1e-3)))
def test_the_rates_own_error_adds_variance_along_the_rate_only(omega, dt, density):
    # gyro_scale_density's share of Q is S_s Δt ω̂ω̂ᵀ: positive semi-definite,
    # nothing across the rate (a turn about z leaves the tilt's variance as
    # it was), S_s Δt |ω̂|² along it, and the rest of Q bit for bit as without
    # it. ``floor``: the rounding of the sum Q₁₁ + the share, a few ulps of Q₁₁.
    omega = np.asarray(omega)
    _, without = discrete_error_model(omega, dt, 1e-6, 1e-5)
    _, with_ = discrete_error_model(omega, dt, 1e-6, 1e-5, density)
    added = (with_ - without)[:3, :3]
    assert np.array_equal(with_[3:], without[3:]) and np.array_equal(with_[:, 3:],
                                                                      without[:, 3:])
    assert np.array_equal(added, added.T)
    floor = 1e-14 * np.abs(with_[:3, :3]).max()
    across = np.cross(omega, [0.3, -0.5, 0.8])
    assert abs(across @ added @ across) <= floor * (across @ across)
    along = density * dt * (omega @ omega) ** 2
    assert abs(omega @ added @ omega - along) <= floor * (omega @ omega) + 1e-9 * along
    assert np.linalg.eigvalsh(added).min() >= -floor


toml_values = st.one_of(st.integers(-10 ** 6, 10 ** 6), st.floats(allow_nan=True),
                        st.text(max_size=5), st.booleans(),
                        st.lists(st.floats(-10, 10), max_size=5))
keys = st.sampled_from(["tstop", "dt", "gyro_noise", "pc_exponent", "wobble",
                        "initial_rate_radps", "initial_attitude_quat",
                        "time_between_measurements", "star_tracker_model"])
section_keys = st.sampled_from(["noise_power", "bias_random_walk", "sigma_arcsec", "model",
                                "interval_s", "initial_bias_deg_per_hr", "nonsense"])


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(keys, toml_values, max_size=4),
       st.dictionaries(st.sampled_from(["gyro", "star_tracker", "truth"]),
                       st.dictionaries(section_keys, toml_values, max_size=3), max_size=2))
def test_scenario_loader_never_fails_with_anything_but_a_clear_value_error(flat, sections):
    document = {**flat, **sections}
    try:
        Scenario().replace(**flatten_sections(document))
    except InvalidParameterError as err:
        text = str(err)
        assert "\n" not in text and " = " in text


@settings(max_examples=30)
@given(st.text(max_size=60))
def test_any_text_as_a_scenario_file_is_refused_or_loaded(text):
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "s.toml"
        path.write_text(text)
        try:
            Scenario.from_toml(path)
        except InvalidParameterError as err:
            assert "\n" not in str(err)


log_uniform = lambda low, high: st.floats(np.log10(low), np.log10(high)).map(  # noqa: E731
    lambda exponent: float(10.0 ** exponent))
small_vectors = lambda bound: st.lists(st.floats(-bound, bound), min_size=3,  # noqa: E731
                                       max_size=3)


@st.composite
def engine_cases(draw):
    """A short random scenario (either sensor model, every estimator option the
    kernels implement) and a run's settings."""
    common = dict(
        tstop=draw(st.sampled_from([0.5, 1.0, 2.0])),
        initial_attitude_quat=draw(unit_quaternions),
        initial_rate_radps=draw(small_vectors(0.3)),
        gyro_initial_bias_radps=draw(small_vectors(1e-3)),
        gyro_bias_random_walk=draw(st.sampled_from([0.0, 1e-9, 1e-6])),
        initial_state=draw(unit_quaternions),
        # The EKF's P₀ against the tracker's R (derived: arcsec² in quaternion
        # units, down to 6e-12): its Joseph update forms I − K with K ≈ P/(P+R),
        # so P₀/R of 1e8 and more amplifies the two paths' different rounding
        # past 1e-9 (measured: 2e-9 at P₀/R = 4e8). Keep it below 1e4.
        initial_covariance=draw(st.sampled_from([1e-12, 1e-10, 1e-9])),
        estimator_options={
            "dead-reckoning": {"rate_timing": draw(st.sampled_from(["workshop", "step-average",
                                                                    "end"]))},
            "dead-reckoning-resets": {
                "rate_timing": draw(st.sampled_from(["workshop", "step-average", "end"])),
                "align_sign": draw(st.booleans())},
            "ekf": {"output": draw(st.sampled_from(["prior", "posterior"])),
                    "align_sign": draw(st.booleans()),
                    "rate_interpolation": draw(st.sampled_from(["hold", "end"]))},
            "mekf": {"output": draw(st.sampled_from(["prior", "posterior"]))},
            "usque": {"output": draw(st.sampled_from(["prior", "posterior"])),
                      "alpha": draw(st.sampled_from([1.0, 0.5, 1e-2])),
                      # κ = 3 − n = -3 is Julier's choice.
                      "kappa": draw(st.sampled_from([0.0, -3.0, 1.0]))}})
    if draw(st.booleans()):
        # Real trackers: a few arcsec to a few arcmin across the boresight, roll up
        # to ten times worse. (R's conditioning bounds how far the two paths'
        # different matrix inverses may drift apart: cond 1e7 reaches 1e-9.)
        cross = draw(st.floats(1.0, 300.0))
        common.update(star_tracker_model="rotation",
                      star_tracker_sigma_arcsec=[cross, cross * draw(st.floats(0.5, 2.0)),
                                                 cross * draw(st.floats(1.0, 10.0))],
                      star_tracker_dropout_probability=draw(st.floats(0.0, 0.5)),
                      star_tracker_sign=draw(st.sampled_from(["raw", "canonical"])),
                      star_tracker_outages_s=draw(st.sampled_from([(), ((0.3, 0.7),)])),
                      star_tracker_to_body_quat=draw(unit_quaternions))
    run = dict(seed=draw(st.integers(0, 2**63 - 1)),
               gyro_noise=draw(log_uniform(1e-14, 1e-4)),
               star_tracker_noise=draw(log_uniform(1e-10, 1e-4)),
               time_between_measurements=0.01 * draw(st.integers(1, 40)),
               pc_exponent=draw(st.floats(-30.0, -3.0)))
    return Scenario(**common), run


# Every case costs a few hundred steps on both paths (1,000 cases passed once).
@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(engine_cases())
def test_engine_equals_the_per_run_path_on_random_scenarios(case):
    from benchmarks.engine import ENGINE_ESTIMATORS, make_runs, run_batch
    from benchmarks.simulation import simulate
    scenario, run = case
    seed = run.pop("seed")
    batch = run_batch(scenario, make_runs(scenario, [seed], **run), ENGINE_ESTIMATORS,
                      keep_traces=True, block_steps=37)
    reference = simulate(scenario.replace(**run), ENGINE_ESTIMATORS, seed=seed)
    for name in ENGINE_ESTIMATORS:
        difference = np.abs(batch.estimates[name][0] - reference.estimates[name]).max()
        assert difference < 1e-9, (name, difference)
