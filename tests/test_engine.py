"""The batched engine: cross-checked against the filterpy path, deterministic,
and its streaming statistics within their stated error."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from benchmarks import Scenario, error_statistics, simulate
from benchmarks.engine import MEDIAN_RELATIVE_ERROR, make_runs, run_batch
from benchmarks.metrics import attitude_error_deg
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


def test_a_run_is_bit_identical_whatever_the_threads():
    """The kernels' runs go one share per thread (benchmarks.engine.kernels.
    cores): one thread or as many as numba has, every number the same."""
    import numba
    previous, most = numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS
    if most < 2:
        pytest.skip("numba has one thread here: nothing to compare")
    runs = make_runs(SCENARIO, np.arange(7))
    results = []
    try:
        for threads in sorted({1, most}):
            numba.set_num_threads(threads)
            results.append(run_batch(SCENARIO, runs, keep_traces=True))
    finally:
        numba.set_num_threads(previous)
    for other in results[1:]:
        for name in results[0].estimators:
            assert np.array_equal(results[0].estimates[name], other.estimates[name])
            for column, values in results[0].statistics[name].items():
                assert np.array_equal(values, other.statistics[name][column], equal_nan=True)


@njit(nogil=True)
def _visit(first, last, visits):
    """A kernel's loop that only counts the runs it is given."""
    for run in range(first, last):
        visits[run] += 1


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 40), st.integers(1, 4))
def test_the_shares_cover_every_run_once(n_runs, threads):
    """on_every_core splits the runs into contiguous shares: each run is
    advanced exactly once, whatever the count of runs and of threads."""
    from benchmarks.engine.kernels.cores import on_every_core
    visits = np.zeros(n_runs, dtype=np.int64)
    on_every_core(_visit, n_runs, visits, threads=threads)
    assert (visits == 1).all()


def test_every_share_finishes_before_an_error_is_raised():
    """A share that raises: every share already taken still finishes before
    the error reaches the caller (no thread left writing into the state),
    and no share is taken after it."""
    import threading
    import time
    from benchmarks.engine.kernels.cores import on_every_core, share_bounds
    started, done, lock, raised = [], [], threading.Lock(), threading.Event()

    def advance_runs(first, last, out):
        with lock:
            started.append(first)
        if first == 0:
            raised.set()
            raise ValueError("share 0")
        raised.wait(10.0)    # share 0 has raised: the taking stops within the sleep
        time.sleep(0.05)
        with lock:
            done.append(first)
    with pytest.raises(ValueError, match="share 0"):
        on_every_core(advance_runs, 64, None, threads=2)
    assert 0 in started and sorted(done) == sorted(set(started) - {0})
    # Two threads take the first two shares at once; after the error, the
    # other thread finishes its share and takes no more.
    assert len(started) <= 2 < len(share_bounds(64, 2)) - 1


@pytest.mark.parametrize("n_runs, threads, shares", [(1, 2, 1), (20, 2, 2), (64, 2, 4),
                                                      (1024, 2, 16), (1024, 1, 8)])
def test_shares_are_several_a_thread_where_the_runs_allow(n_runs, threads, shares):
    """Several shares a thread (SHARES_PER_THREAD), each of MIN_SHARE_RUNS
    runs at least, one a thread at least (fewer threads than runs)."""
    from benchmarks.engine.kernels.cores import share_bounds
    bounds = share_bounds(n_runs, min(threads, n_runs))
    assert len(bounds) - 1 == shares and bounds[0] == 0 and bounds[-1] == n_runs
    assert np.all(np.diff(bounds) > 0)


def test_only_requested_estimators_run():
    batch = run_batch(SCENARIO, make_runs(SCENARIO, [3]), ["ekf"])
    assert batch.estimators == ("ekf",) and set(batch.statistics) == {"ekf"}
    frame = batch.frame()
    assert list(frame["estimator"]) == ["ekf"] and frame["seed"].tolist() == [3]


@pytest.mark.parametrize("settings, name", [
    ({"pc_exponent": [np.nan]}, "pc_exponent"),
    ({"time_between_measurements": [0.005]}, "time_between_measurements"),
    ({"gyro_noise": [-1.0]}, "gyro_noise"),
    ({"inertia": 1}, "inertia"),
])
def test_bad_run_settings_rejected(settings, name):
    with pytest.raises(InvalidParameterError, match=name):
        make_runs(SCENARIO, [0], **settings)


def test_unknown_estimator_rejected():
    with pytest.raises(InvalidParameterError, match="estimator"):
        run_batch(SCENARIO, make_runs(SCENARIO, [0]), ["ukf"])


FLIGHT_FILE = __import__("pathlib").Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml"
#: The flight scenario, shortened, with every sensor feature switched on.
FLIGHT = Scenario.from_toml(FLIGHT_FILE).replace(
    tstop=60.0, star_tracker_dropout_probability=0.2, star_tracker_outages_s=((12.0, 17.5),),
    star_tracker_sign="canonical", initial_attitude_quat=[0.0, 0.6, 0.0, 0.8],
    gyro_scale_misalignment=[[1e-3, 2e-4, 0.0], [0.0, -5e-4, 1e-4], [3e-4, 0.0, 2e-3]],
    star_tracker_to_body_quat=[0.9, 0.1, -0.3, 0.2])
ALL = ("dead-reckoning", "dead-reckoning-resets", "ekf", "mekf", "usque")


@pytest.fixture(scope="module")
def flight_batch():
    runs = make_runs(FLIGHT, seeds=[0, 5, 9], gyro_noise=[1e-13, 4e-12, 1e-13],
                     time_between_measurements=[1.0, 0.5, 2.0], pc_exponent=[-28.5, -25.0, -30])
    return runs, run_batch(FLIGHT, runs, ALL, keep_traces=True, block_steps=77)


def test_flight_engine_equals_the_per_run_path_at_every_step(flight_batch):
    runs, batch = flight_batch
    for i in range(len(runs)):
        case = FLIGHT.replace(gyro_noise=float(runs.gyro_noise[i]),
                              time_between_measurements=float(runs.time_between_measurements[i]),
                              pc_exponent=float(runs.pc_exponent[i]))
        reference = simulate(case, ALL, seed=int(runs.seeds[i]), traces=True)
        scheduled = len(reference.time_s[::round(case.time_between_measurements / case.dt)])
        assert reference.sensors.available.sum() < scheduled - 5   # dropouts and the outage bite
        for name in ALL:
            difference = np.abs(batch.estimates[name][i] - reference.estimates[name])
            assert difference.max() < 1e-9, (i, name, difference.max())
        # USQUE's sums cancel differently on the two paths: its bias is a
        # weighted mean of sigma points ±√6 σ_β apart (about 1e-15 rad/s of a
        # 1e-6 bias), and its first update's P − K S Kᵀ takes from a 0.36 rad²
        # prior a number equal to it to 3e-8 (eps × 0.36 / 1e-8 ≈ 4e-9 relative).
        for name, rtol in (("mekf", 1e-9), ("usque", 1e-7)):
            trace = reference.traces[name]
            assert np.allclose(batch.final[name]["bias_radps"][i], trace.bias_radps[-1],
                               rtol=rtol, atol=1e-18)
            assert np.allclose(batch.final[name]["covariance"][i][:3, :3],
                               trace.attitude_covariance[-1], rtol=rtol, atol=0)
            assert np.allclose(batch.attitude_variances[name][i],
                               np.diagonal(trace.attitude_covariance, axis1=1, axis2=2),
                               rtol=rtol, atol=0)
        assert np.allclose(batch.final["gyro_bias_radps"][i], reference.sensors.gyro_bias_radps[-1],
                           rtol=1e-12, atol=0)


def test_flight_runs_are_bit_identical_whatever_their_batch(flight_batch):
    runs, batch = flight_batch
    alone = run_batch(FLIGHT, runs.take([1]), ALL, keep_traces=True, block_steps=1000)
    for name in ALL:
        assert np.array_equal(alone.estimates[name][0], batch.estimates[name][1])


@pytest.mark.parametrize("name", ["mekf", pytest.param("usque", marks=pytest.mark.slow)])
def test_six_state_filters_on_workshop_sensors_equal_the_per_run_path(name):    # USQUE: 4 s
    runs = make_runs(SCENARIO, seeds=[2, 3], star_tracker_noise=[1e-6, 4e-6])
    batch = run_batch(SCENARIO, runs, [name], keep_traces=True)
    for i in range(2):
        case = SCENARIO.replace(star_tracker_noise=float(runs.star_tracker_noise[i]))
        reference = simulate(case, [name], seed=int(runs.seeds[i]))
        assert np.abs(batch.estimates[name][i] - reference.estimates[name]).max() < 1e-9


def test_engine_streams_the_per_run_nees_and_nis(flight_batch):
    from benchmarks.metrics import nees
    runs, _ = flight_batch
    batch = run_batch(FLIGHT, runs, ["dead-reckoning", "ekf", "mekf", "usque"],
                      consistency=True, nees_every=7, settle_steps=50)
    assert set(batch.consistency) == {"ekf", "mekf", "usque"}
    for i in range(len(runs)):
        case = FLIGHT.replace(gyro_noise=float(runs.gyro_noise[i]),
                              time_between_measurements=float(runs.time_between_measurements[i]),
                              pc_exponent=float(runs.pc_exponent[i]))
        reference = simulate(case, ["ekf", "mekf", "usque"], seed=int(runs.seeds[i]),
                             traces=True)
        for name in ("ekf", "mekf", "usque"):
            trace = reference.traces[name]
            from dynamics.quaternion import attitude_error_vector_rad
            expected = nees(attitude_error_vector_rad(reference.truth.q_true, trace.quat),
                            trace.attitude_covariance)
            streamed = batch.consistency[name]
            assert np.allclose(streamed["nees_samples"][i], expected[::7], rtol=1e-6)
            assert streamed["nees_time_average"][i] == pytest.approx(expected[50:].mean(),
                                                                     rel=1e-6)
            assert streamed["nis_mean"][i] == pytest.approx(np.nanmean(trace.nis), rel=1e-6)
            assert streamed["nis_dof"] == trace.nis_dof


def test_the_streamed_truth_is_the_cached_truth_bit_for_bit():
    # The engine integrates long runs block by block; it must be solve_ivp's numbers.
    from dynamics.rigid_body import torque_free_blocks
    from benchmarks.simulation import simulate_truth
    scenario = Scenario.from_toml(FLIGHT_FILE).replace(tstop=600.0)
    whole = simulate_truth(scenario)
    for block_steps in (1, 997, 6001, 10**6):
        blocks = list(torque_free_blocks(scenario.inertia_tensor_kg_m2,
                                         scenario.initial_attitude_quat,
                                         scenario.initial_rate_radps, scenario.dt,
                                         scenario.n_steps, block_steps))
        assert [len(b.time_s) for b in blocks[:-1]] == [block_steps] * (len(blocks) - 1)
        for name in ("time_s", "q_true", "omega_true_radps"):
            joined = np.concatenate([getattr(b, name) for b in blocks])
            assert np.array_equal(joined, getattr(whole, name)), (block_steps, name)


def test_a_batch_streaming_its_truth_equals_one_holding_it(flight_batch):
    runs, _ = flight_batch
    held = run_batch(FLIGHT, runs, ALL)
    streamed = run_batch(FLIGHT, runs, ALL, cache_steps=10, block_steps=333)
    for name in held.estimators:
        for column, values in held.statistics[name].items():
            assert np.array_equal(values, streamed.statistics[name][column]), (name, column)


def test_the_health_checks_count_what_they_should():
    from benchmarks.engine.kernels import common as kernels
    counts, factor = np.zeros(kernels.N_HEALTH), np.empty((6, 6))
    good = np.diag([1.0, 2.0, 3.0])
    kernels.check_health(np.array([1.0, 0, 0, 0]), True, good, 3, counts, factor)
    assert counts[kernels.CHECKS] == 1 and counts[1:kernels.WORST_NORM].sum() == 0
    kernels.check_health(np.array([1.0 + 1e-9, 0, 0, 0]), True, good, 3, counts, factor)
    assert counts[kernels.NORM_OFF] == 1 and counts[kernels.WORST_NORM] > 9e-10
    kernels.check_health(np.array([2.0, 0, 0, 0]), False, good, 3, counts, factor)
    assert counts[kernels.NORM_OFF] == 1                     # not unit by design: not counted
    skewed = good.copy()
    skewed[0, 1] = 1e-6
    kernels.check_health(np.array([1.0, 0, 0, 0]), True, skewed, 3, counts, factor)
    assert counts[kernels.ASYMMETRIC] == 1 and counts[kernels.NOT_POSITIVE_DEFINITE] == 0
    indefinite = np.array([[1.0, 2.0, 0], [2.0, 1.0, 0], [0, 0, 1.0]])   # eigenvalue -1
    kernels.check_health(np.array([1.0, 0, 0, 0]), True, indefinite, 3, counts, factor)
    assert counts[kernels.NOT_POSITIVE_DEFINITE] == 1 and counts[kernels.ASYMMETRIC] == 1
    kernels.check_health(np.array([np.nan, 0, 0, 0]), True, good, 3, counts, factor)
    assert counts[kernels.NON_FINITE] == 1 and counts[kernels.NORM_OFF] == 2
    assert counts[kernels.CHECKS] == 6


def test_a_healthy_flight_batch_passes_every_check(flight_batch):
    runs, _ = flight_batch
    batch = run_batch(FLIGHT, runs, ALL, health=True)
    for name, health in batch.health.items():
        assert np.all(health["checks"] >= FLIGHT.n_steps), name
        for column in ("norm_off", "asymmetric", "not_positive_definite", "non_finite"):
            assert not health[column].any(), (name, column)


def test_sampled_errors_are_the_traces_errors_every_m_steps(flight_batch):
    runs, batch = flight_batch
    sampled = run_batch(FLIGHT, runs, ALL, error_every=7)
    from benchmarks.simulation import simulate_truth
    truth = simulate_truth(FLIGHT)
    assert np.array_equal(sampled.sample_time_s, truth.time_s[::7])
    for name in ALL:
        expected = attitude_error_deg(truth.q_true[::7], batch.estimates[name][:, ::7])
        assert sampled.error_samples[name].shape == expected.shape
        assert np.allclose(sampled.error_samples[name], expected, rtol=1e-12, atol=1e-12), name


def test_the_soak_benchmark_reports_every_estimator(capsys):
    from benchmarks import soak
    assert soak.main(["--steps", "2000", "--runs", "1", "--every", "10",
                      "--no-memory-comparison", "--quiet"]) == 0
    out = capsys.readouterr().out
    for name in ALL:
        assert out.count(f"  {name} ") == 2, name      # a health row and a stationarity row
    assert "NaN/inf" in out and "peak resident memory" in out


def test_resets_align_a_reading_with_the_prediction_as_the_per_run_class_does():
    # Found by the property test: an estimate about 90° from the reading, where
    # the un-propagated and the propagated estimate disagree on the sign.
    scenario = Scenario(tstop=0.05, initial_state=[0.0, 1.0, 0.0, 0.0],
                        initial_rate_radps=[0.3, 0.0, 0.0])
    settings = dict(gyro_noise=1e-4, star_tracker_noise=1e-7, time_between_measurements=0.01,
                    pc_exponent=-3.0)
    batch = run_batch(scenario, make_runs(scenario, [0], **settings), ["dead-reckoning-resets"],
                      keep_traces=True)
    reference = simulate(scenario.replace(**settings), ["dead-reckoning-resets"], seed=0)
    assert np.abs(batch.estimates["dead-reckoning-resets"][0]
                  - reference.estimates["dead-reckoning-resets"]).max() < 1e-9


def test_the_kernel_compiles_once_whatever_the_block_lengths():
    # A shorter last block used to reach the kernel as a strided view, a
    # second signature and a second cold compile (about 40 s on a fresh machine).
    from benchmarks.engine.kernels import KERNELS, kernel
    for block_steps in (333, 1000):                 # 2001 = 6 x 333 + 3
        run_batch(SCENARIO, make_runs(SCENARIO, [0, 1]), list(KERNELS),
                  block_steps=block_steps)
    for name in KERNELS:
        assert len(kernel(name).advance_runs.signatures) == 1, \
            (name, kernel(name).advance_runs.signatures)


def test_a_constant_bias_without_a_walk_reads_no_normals_past_its_row():
    """A gyro with a bias but no bias walk draws 3 normals a step; the bias
    step must not read a fourth (past the row: a neighbour's noise, or past
    the buffer's end, where NaN made a run diverge now and then)."""
    from benchmarks.engine.kernels.sensors import _flight_gyro
    buffer = np.full(6, np.nan)
    buffer[:3] = [0.1, -0.2, 0.3]
    normals = buffer[:3]                   # the row; NaN right after it
    w, bias, bias_last = np.empty(3), np.array([1e-4, 0.0, -2e-4, 0, 0, 0]), np.zeros(3)
    no_walk = np.array([0.0, 1.0, 0.0, 0.0, 0.0])      # no walk, no Gauss–Markov part
    _flight_gyro(w, np.array([0.01, 0.02, 0.03]), 1e-3, normals, np.zeros((3, 3)), False, True,
                 no_walk, bias, bias_last, False)
    np.testing.assert_array_equal(bias, [1e-4, 0.0, -2e-4, 0, 0, 0])
    np.testing.assert_allclose(w, [0.01 + 1e-4 + 1e-4, 0.02 - 2e-4, 0.03 - 2e-4 + 3e-4],
                               rtol=1e-12)


@settings(max_examples=8, deadline=None)
@given(st.lists(st.sampled_from([3, 5]), min_size=2, max_size=6),
       st.lists(st.sampled_from([0.05, 0.2]), min_size=6, max_size=6),
       st.lists(st.sampled_from([-8.7, -6.0, -11.0]), min_size=6, max_size=6))
def test_runs_that_share_a_seed_draw_what_each_draws_alone(seeds, intervals, pcs):
    # Runs with one seed and one tracker interval share their streams (drawn
    # once, copied); each still gets exactly its own numbers: the batch equals
    # every run alone, bit for bit, through several blocks, the tracker's
    # dropouts and the gyro's Gauss–Markov start included.
    scenario = Scenario(tstop=2.0).replace(star_tracker_dropout_probability=0.3,
                                           gyro_bias_instability_radps=1e-4,
                                           gyro_bias_correlation_time_s=50.0)
    n = len(seeds)
    runs = make_runs(scenario, seeds=seeds, time_between_measurements=intervals[:n],
                     pc_exponent=pcs[:n], gyro_noise=[1e-5 * (1 + i) for i in range(n)])
    names = ("ekf", "mekf")
    batch = run_batch(scenario, runs, names, keep_traces=True, block_steps=64)
    for i in range(n):
        alone = run_batch(scenario, runs.take([i]), names, keep_traces=True, block_steps=64)
        for name in names:
            assert np.array_equal(alone.estimates[name][0], batch.estimates[name][i]), (i, name)
        assert np.array_equal(alone.final["gyro_bias_radps"][0], batch.final["gyro_bias_radps"][i])


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), runs=st.integers(1, 12), low=st.integers(0, 3000),
       width=st.integers(1, 500), lost=st.integers(0, 3))
def test_the_histogram_median_sums_only_the_bins_some_run_holds(seed, runs, low, width, lost):
    # The same medians, to the bit, as the cumulative counts of every bin
    # (the formula before the sums skipped the empty bins): runs whose
    # errors lie anywhere, and runs cut short (diverged: fewer counts than
    # the steps, their median 0 before the NaN their statistics get).
    from benchmarks.engine.results import HISTOGRAM_BINS
    from benchmarks.engine.results import bin_edge, histogram_median
    rng = np.random.default_rng(seed)
    hist = np.zeros((runs, HISTOGRAM_BINS), dtype=np.uint32)
    steps = 1000
    for r in range(runs):
        held = low + rng.integers(0, width, steps if r >= lost else steps // 3)
        np.add.at(hist[r], np.minimum(held, HISTOGRAM_BINS - 1), 1)
    cumulative = np.cumsum(hist.astype(np.int64), axis=1)
    rank = (steps - 1) / 2.0
    index = np.argmax(cumulative > rank, axis=1)
    rows = np.arange(runs)
    before = np.where(index > 0, cumulative[rows, index - 1], 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = (rank - before + 0.5) / hist[rows, index]
    safe = np.maximum(index, 1)
    expected = np.where(index == 0, 0.0,
                        bin_edge(safe) + fraction * (bin_edge(safe + 1) - bin_edge(safe)))
    assert np.array_equal(histogram_median(hist, steps), expected, equal_nan=True)
