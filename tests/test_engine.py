"""The batched engine: cross-checked against the filterpy path, deterministic,
and its streaming statistics within their stated error."""
import numpy as np
import pytest

from benchmarks import Scenario, error_statistics, simulate
from benchmarks.engine import MEDIAN_RELATIVE_ERROR, make_runs, run_batch
from dynamics.validation import InvalidParameterError

SCENARIO = Scenario(tstop=20.0)
EXACT_COLUMNS = ("mean_deg", "std_deg", "three_sigma_deg", "rms_deg", "max_deg", "final_deg")


@pytest.fixture(scope="module")
def mixed_batch():
    """Seeds, pc exponents, star tracker intervals and noise powers all varied."""
    runs = make_runs(SCENARIO, seeds=[0, 1, 7, 42],
                     pc_exponent=[-8.7, -12.0, -4.5, -8.7],
                     time_between_measurements=[0.2, 0.5, 0.03, 1.0],
                     gyro_noise=[1e-5, 1e-4, 1e-6, 1e-5],
                     star_tracker_noise=[1e-6, 1e-6, 1e-5, 0.0])
    return runs, run_batch(SCENARIO, runs, keep_traces=True, block_steps=333)


def per_run_reference(runs, i):
    case = SCENARIO.replace(**{name: float(getattr(runs, name)[i]) for name in
                               ("pc_exponent", "time_between_measurements", "gyro_noise",
                                "star_tracker_noise")})
    return simulate(case, seed=int(runs.seeds[i]))


def test_estimates_equal_filterpy_path_at_every_step(mixed_batch):
    runs, batch = mixed_batch
    for i in range(len(runs)):
        reference = per_run_reference(runs, i)
        for name in ("dead-reckoning", "dead-reckoning-resets", "ekf"):
            difference = np.abs(batch.estimates[name][i] - reference.estimates[name])
            assert difference.max() < 1e-9, (i, name, difference.max())


def test_statistics_equal_filterpy_path(mixed_batch):
    runs, batch = mixed_batch
    for i in range(len(runs)):
        reference = per_run_reference(runs, i)
        for name, error in reference.error_deg.items():
            expected = error_statistics(error)
            for column in EXACT_COLUMNS + ("median_deg",):   # traces kept: exact median
                assert batch.statistics[name][column][i] == pytest.approx(
                    expected[column], rel=1e-9, abs=1e-12), (i, name, column)


def test_streaming_statistics_match_kept_traces():
    runs = make_runs(SCENARIO, seeds=range(24), pc_exponent=np.linspace(-14, -2, 24))
    streamed = run_batch(SCENARIO, runs)
    exact = run_batch(SCENARIO, runs, keep_traces=True)
    assert streamed.estimates is None
    for name in exact.estimators:
        for column in EXACT_COLUMNS:
            assert np.array_equal(streamed.statistics[name][column],
                                  exact.statistics[name][column])
        # The histogram median's documented bound: one bin, 2⁻⁷ relative.
        ratio = streamed.statistics[name]["median_deg"] / exact.statistics[name]["median_deg"]
        assert np.all(np.abs(ratio - 1) <= MEDIAN_RELATIVE_ERROR)
    assert MEDIAN_RELATIVE_ERROR < 0.008


def test_a_run_is_bit_identical_whatever_its_batch():
    seeds = np.arange(20, 52)
    big = run_batch(SCENARIO, make_runs(SCENARIO, seeds))
    alone = run_batch(SCENARIO, make_runs(SCENARIO, [seeds[5]]), block_steps=77)
    other_blocks = run_batch(SCENARIO, make_runs(SCENARIO, seeds[3:9]), block_steps=2001)
    for name in big.estimators:
        for column, values in big.statistics[name].items():
            assert values[5] == alone.statistics[name][column][0]
            assert values[5] == other_blocks.statistics[name][column][2]


def test_only_requested_estimators_run():
    batch = run_batch(SCENARIO, make_runs(SCENARIO, [3]), ["ekf"])
    assert batch.estimators == ("ekf",) and set(batch.statistics) == {"ekf"}
    frame = batch.frame()
    assert list(frame["estimator"]) == ["ekf"] and frame["seed"].tolist() == [3]


@pytest.mark.parametrize("settings, name", [
    ({"pc_exponent": [np.nan]}, "pc_exponent"),
    ({"time_between_measurements": [0.015]}, "time_between_measurements"),
    ({"gyro_noise": [-1.0]}, "gyro_noise"),
    ({"inertia": 1}, "inertia"),
])
def test_bad_run_settings_rejected(settings, name):
    with pytest.raises(InvalidParameterError, match=name):
        make_runs(SCENARIO, [0], **settings)


def test_unknown_estimator_rejected():
    with pytest.raises(InvalidParameterError, match="estimator"):
        run_batch(SCENARIO, make_runs(SCENARIO, [0]), ["ukf"])
