"""Values of the wrong type or beyond what a double can hold are refused at
the boundary, in one line naming the parameter, the value and the rule:
booleans are not numbers, text is not a boolean, a σ's square must be
finite, recordings hold real numbers and begin at rest, USQUE's sigma points
need a positive definite covariance, a user's class must be a concrete
estimator, and reading a file imports nobody's code without consent."""
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from benchmarks import Scenario, simulate
from dynamics.validation import (
    InvalidParameterError,
    axis_standard_deviations,
    boolean,
    covariance_matrix,
    finite_vector,
    inertia_tensor,
    nonzero_quaternion,
    standard_deviation,
)
from estimators import USQUE, resolve_estimator
from sensors.recording import load_recording

FLIGHT = Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml"


def refused(call, *args, **kwargs) -> str:
    """The one-line message ``call`` refuses with; no numpy warning on the way."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InvalidParameterError) as info:
            call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# 1. Booleans (and text, and complex numbers) are not numbers.

@pytest.mark.parametrize("call, value", [
    (lambda v: finite_vector("v", v, 3), [True, 0, 0]),
    (lambda v: finite_vector("v", v, 3), np.array([True, False, False])),
    (lambda v: finite_vector("v", v, 3), (0.0, np.False_, 1.0)),
    (lambda v: nonzero_quaternion("v", v), [np.True_, 0, 0, 0]),
    (lambda v: inertia_tensor("v", v), [1.0, True, 2.0]),
    (lambda v: covariance_matrix("v", v, 3), True),
    (lambda v: covariance_matrix("v", v, 3), [[1, 0, 0], [0, True, 0], [0, 0, 1]]),
])
def test_booleans_in_a_numeric_vector_or_matrix_are_refused(call, value):
    assert refused(call, value).endswith(": must be numbers, not true/false")


@pytest.mark.parametrize("value, rule", [
    (["1", 0, 0], "must be numbers, not text"),
    (np.array(["1", "0", "0"]), "must be numbers, not text"),
    (np.array([1j, 0, 0]), "must be real numbers, not complex"),
])
def test_text_and_complex_numbers_are_not_converted(value, rule):
    assert refused(finite_vector, "v", value, 3).endswith(rule)


def test_a_true_in_a_scenario_files_vector_is_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[truth]\ninitial_rate_radps = [true, 0, 0]\n")
    assert refused(Scenario.from_toml, path) == (
        "initial_rate_radps = [True, 0, 0]: must be numbers, not true/false")
    path.write_text("[gyro]\ninitial_bias_deg_per_hr = [0, false, 0]\n")
    assert "must be numbers, not true/false" in refused(Scenario.from_toml, path)
    assert np.array_equal(Scenario(initial_rate_radps=[1, 0, 0]).initial_rate_radps, [1, 0, 0])


# 2. Text is never coerced to a boolean.

def test_boolean_accepts_only_real_booleans():
    assert boolean("align_sign", True) is True and boolean("align_sign", np.False_) is False
    for value in ("false", "true", 0, 1, None):
        assert refused(boolean, "align_sign", value) == (
            f"align_sign = {value!r}: must be true or false (a boolean, not text or a number)")


@pytest.mark.parametrize("name", ["ekf", "dead-reckoning-resets"])
def test_align_sign_from_a_file_is_not_coerced(tmp_path, name):
    path = tmp_path / "s.toml"
    path.write_text(f'[estimators.{name}]\nalign_sign = "false"\n')
    assert "must be true or false" in refused(Scenario.from_toml, path)


# 3. A σ whose square overflows is refused up front.

def test_a_standard_deviation_must_have_a_finite_square():
    assert standard_deviation("s", 1e154) == 1e154            # 1e308 is still finite
    rule = "must be below 1.34e+154 so that its square (a variance) is finite"
    assert refused(standard_deviation, "s", 1.4e154) == f"s = 1.4e+154: {rule}"
    assert refused(axis_standard_deviations, "s", [1.0, 1e155, 1.0]).endswith(rule)
    assert refused(axis_standard_deviations, "s", [1.0, -1.0, 1.0]).endswith("must be >= 0")
    assert np.array_equal(axis_standard_deviations("s", 2.0), [2.0, 2.0, 2.0])


@pytest.mark.parametrize("content, name", [
    ("[gyro]\nbias_random_walk = 1e200\n", "gyro_bias_random_walk"),
    ("[gyro]\narw_deg_per_rthr = 1e200\n", "gyro.arw_deg_per_rthr"),
    ("[gyro]\nbias_rw_deg_per_hr_rthr = 1e200\n", "gyro.bias_rw_deg_per_hr_rthr"),
    ("[star_tracker]\nsigma_arcsec = [1e200, 6, 40]\n", "star_tracker_sigma_arcsec"),
])
def test_sensor_sigmas_whose_square_overflows_are_refused(tmp_path, content, name):
    path = tmp_path / "s.toml"
    path.write_text(content)
    message = refused(Scenario.from_toml, path)
    assert message.startswith(f"{name} = ") and "so that its square (a variance)" in message


def test_the_mekfs_initial_sigma_whose_square_overflows_is_refused():
    options = {"mekf": {"initial_attitude_sigma_rad": 1e200}}
    assert "so that its square" in refused(Scenario, estimator_options=options)


def test_a_covariance_matrix_given_directly_must_be_finite():
    matrix = np.eye(4)
    matrix[1, 1] = np.inf
    assert refused(covariance_matrix, "R", matrix).endswith(": must be finite")
    matrix[1, 1] = np.nan
    assert refused(covariance_matrix, "R", matrix).endswith(": must be finite")


# 4. Recordings hold real numbers, and begin at rest.

def _recording(tmp_path, **changes):
    """100 samples at rest for 20, then moving, with ``changes``."""
    data = {"imu_gyr_radps": np.zeros((100, 3)), "opt_quat": np.tile([1.0, 0, 0, 0], (100, 1)),
            "movement": np.arange(100) >= 20, "sampling_rate_hz": np.array(100.0)}
    data.update(changes)
    path = tmp_path / "mine.npz"
    np.savez(path, **data)
    return path


@pytest.mark.parametrize("changes, rule", [
    ({"imu_gyr_radps": np.zeros((100, 3)) + 1e-3j},
     "imu_gyr_radps must hold real numbers; it holds complex numbers"),
    ({"opt_quat": np.tile([1.0 + 0j, 0, 0, 0], (100, 1))},
     "opt_quat must hold real numbers; it holds complex numbers"),
    ({"imu_gyr_radps": np.full((100, 3), "0.1")}, "imu_gyr_radps must hold real numbers; it "
                                                  "holds text"),
    ({"imu_gyr_radps": np.zeros((100, 3), dtype=bool)},
     "imu_gyr_radps must hold real numbers; it holds true/false"),
    ({"imu_gyr_radps": np.zeros((100, 3)).astype(object)},
     "imu_gyr_radps cannot be read (Object arrays cannot be loaded when allow_pickle=False)"),
    ({"sampling_rate_hz": np.array(True)}, "sampling_rate_hz must hold real numbers; it holds "
                                           "true/false"),
    ({"sampling_rate_hz": np.array(100.0 + 1j)}, "sampling_rate_hz must hold real numbers"),
    ({"movement": (np.arange(100) >= 20).astype(float)},
     "movement must be true/false (or the integers 0/1) per sample; it holds float64 numbers"),
    ({"movement": (np.arange(100) >= 20) + 0j}, "movement must be true/false"),
])
def test_a_recording_of_the_wrong_types_is_refused_naming_the_key(tmp_path, changes, rule):
    path = _recording(tmp_path, **changes)
    message = refused(load_recording, path)
    assert message.startswith(f"dataset = '{path}': ") and rule in message


def test_a_recording_of_integers_or_only_rest_still_loads(tmp_path):
    recording = load_recording(_recording(tmp_path, movement=(np.arange(100) >= 20).astype(int)))
    assert recording.movement.dtype == bool and recording.rest_samples == slice(0, 20)
    recording = load_recording(_recording(tmp_path, movement=np.zeros(100, bool)))
    assert recording.rest_samples == slice(0, 100)
    assert np.array_equal(recording.rest_gyro_mean_radps(), np.zeros(3))


# 5. USQUE's sigma points need a positive definite covariance.

@pytest.mark.parametrize("settings, start", [
    ({"initial_attitude_sigma_rad": 0.0}, "initial_attitude_sigma_rad = 0.0: must be > 0 on "
                                          "every axis: USQUE's sigma points need a positive "
                                          "definite covariance"),
    ({"initial_attitude_sigma_rad": [0.1, 0.0, 0.1]}, "initial_attitude_sigma_rad = [0.1, 0.0, "
                                                      "0.1]: must be > 0 on every axis"),
    ({"initial_bias_sigma_radps": 0.0}, "initial_bias_sigma_radps = 0.0: must be > 0"),
    ({"alpha": 1e-200}, "alpha = 1e-200: makes n + lambda = alpha^2 (n + kappa) = 0 "),
    ({"alpha": 9.9e-5}, "alpha = 9.9e-05: makes n + lambda = alpha^2 (n + kappa) = 5.88e-08"),
    ({"alpha": 1e200}, "alpha = 1e+200: makes n + lambda = alpha^2 (n + kappa) = inf"),
    ({"kappa": -6 + 5e-8}, "kappa = -5.99999995: makes n + lambda"),
    ({"kappa": -7.0}, "kappa = -7.0: must be > -6 so that n + kappa > 0 (n = 6)"),
    ({"beta": -1.0}, "beta = -1.0: must be >= 0"),
    ({"initial_bias_sigma_radps": 1e-151}, "initial_bias_sigma_radps = 1e-151: makes "
                                           "(n + lambda) sigma^2 = 6e-302"),
    ({"initial_attitude_sigma_rad": 1e150}, "initial_attitude_sigma_rad = 1e+150: makes "
                                            "(n + lambda) sigma^2 = 6e+300"),
])
def test_usque_refuses_settings_its_sigma_points_cannot_take(settings, start):
    assert refused(USQUE, **settings).startswith(start)


@pytest.mark.parametrize("settings", [
    {"alpha": 1e-4}, {"kappa": -6 + 1e-7}, {"alpha": 0.999 * (1e300 / 6) ** 0.5},
    {"initial_bias_sigma_radps": 1e-150}, {"initial_attitude_sigma_rad": [0.6, 1e-140, 0.6]},
])
def test_usque_runs_just_inside_the_limits(settings):
    # As built from the flight scenario, for 20 readings: finite estimates.
    flight = Scenario.from_toml(FLIGHT).replace(tstop=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = simulate(flight.replace(estimator_options={"usque": settings}), ["usque"],
                          seed=0)
    assert np.all(np.isfinite(result.estimates["usque"]))
    assert np.all(result.error_deg["usque"] < 40.0)         # within the flight prior's 3σ


# 6. A user's class must be a concrete estimator; each failure has its message.

@pytest.mark.parametrize("spec, message", [
    ("estimators.base:AttitudeEstimator",
     "AttitudeEstimator is abstract: it does not implement _step and reset"),
    ("estimators.base:AttitudeAndBiasEstimator",
     "AttitudeAndBiasEstimator is abstract: it does not implement reset"),   # its base steps
    ("estimators.base:Nope", "module estimators.base has no class Nope"),
    ("estimators.base:EstimateTrace", "EstimateTrace in estimators.base is not an estimator: "
                                      "it must be a subclass of estimators.AttitudeEstimator"),
    ("estimators.base:axis_sigmas", "axis_sigmas in estimators.base is not an estimator"),
    ("estimators.nowhere:X", "cannot import estimators.nowhere (ModuleNotFoundError: "),
])
def test_a_users_class_that_is_no_concrete_estimator_is_refused(spec, message):
    assert refused(resolve_estimator, spec).startswith(f"estimator = {spec!r}: {message}")


def test_a_class_missing_one_method_is_named_abstract(tmp_path, monkeypatch):
    (tmp_path / "half_done.py").write_text(textwrap.dedent('''
        from estimators import AttitudeEstimator
        class Half(AttitudeEstimator):
            def _step(self, omega, reading=None):
                return self.initial_attitude
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "half_done", raising=False)
    assert refused(resolve_estimator, "half_done:Half").endswith(
        "Half is abstract: it does not implement reset")


# 7. Reading a file imports no code without consent.

USER_MODULE = '''
from pathlib import Path
Path(__file__).with_name("imported.marker").write_text("ran")

from estimators import DeadReckoning


class Mine(DeadReckoning):
    name = "mine"

    def __init__(self, *, gain=0.1, **settings):
        super().__init__(**settings)
        self.gain = gain
'''


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """A module whose top-level code leaves ``imported.marker`` beside it."""
    (tmp_path / "consent_mod.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "consent_mod", raising=False)
    yield tmp_path / "imported.marker"
    sys.modules.pop("consent_mod", None)


def test_a_users_section_is_refused_without_importing_its_module(tmp_path, user_module):
    path = tmp_path / "s.toml"
    path.write_text('tstop = 2.0\n[estimators."consent_mod:Mine"]\ngain = 0.5\n')
    for read in (Scenario.from_toml, Scenario().with_estimator_settings):
        assert refused(read, path) == (
            "estimators.\"consent_mod:Mine\" = {'gain': 0.5}: reading the file would import "
            "consent_mod and run its code; allow it with --allow-import consent_mod or by "
            "naming consent_mod:Mine in --estimators (from Python: "
            "allow_imports=['consent_mod'])")
    assert refused(Scenario.from_toml, path, allow_imports=["other_mod"]).startswith(
        'estimators."consent_mod:Mine"')
    assert not user_module.exists() and "consent_mod" not in sys.modules


@pytest.mark.parametrize("allow", [["consent_mod"], ("consent_mod:Mine",), "consent_mod"])
def test_with_consent_the_section_is_read_and_applied(tmp_path, user_module, allow):
    path = tmp_path / "s.toml"
    path.write_text('tstop = 2.0\n[estimators."consent_mod:Mine"]\ngain = 0.5\n')
    scenario = Scenario.from_toml(path, allow_imports=allow)
    assert user_module.read_text() == "ran"
    assert scenario.tstop == 2.0
    assert scenario.estimator_options == {"consent_mod:Mine": {"gain": 0.5}}
    settings = tmp_path / "settings.toml"
    settings.write_text('[estimators."consent_mod:Mine"]\ngain = 0.25\n')
    laid_over = Scenario().with_estimator_settings(settings, allow_imports=allow)
    assert laid_over.estimator_options["consent_mod:Mine"] == {"gain": 0.25}


def test_registry_sections_need_no_consent_and_bad_consent_is_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[estimators.mekf]\ninitial_attitude_sigma_rad = 0.2\n")
    assert Scenario.from_toml(path).estimator_options == {
        "mekf": {"initial_attitude_sigma_rad": 0.2}}
    assert refused(Scenario.from_toml, path, allow_imports=[3]) == (
        "allow_imports = 3: must be module names or package.module:ClassName specs")
    assert refused(Scenario.from_toml, path, allow_imports=5).startswith("allow_imports = 5")
