"""The EKF's and the MEKF's lanes kernels (eight runs side by side in
vector instructions) against their one-run kernels: the same numbers to
the bit, step by step, in every case they cover
(benchmarks/engine/kernels/ekf_lanes.py, mekf_lanes.py)."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks import Scenario
from benchmarks.engine import make_runs, run_batch
from benchmarks.engine.kernels import ekf_lanes, mekf_lanes

SHORT = Scenario(tstop=3.0)
#: The tracker silent for half a second.
OUTAGE = SHORT.replace(star_tracker_outages_s=((1.0, 1.5),))


#: Each estimator with a lanes kernel, and that kernel's module.
LANES_KERNELS = {"ekf": ekf_lanes, "mekf": mekf_lanes}


def both_kernels(scenario, runs, threads=None, name="ekf", **options):
    """Estimator ``name``'s batch on its lanes kernel, then on its one-run
    kernel (each error kept at every step unless ``error_every`` says
    otherwise), on ``threads`` of numba's (default: as many as it has); and
    how many shares the lanes kernel took."""
    import numba
    module = LANES_KERNELS[name]
    calls, lanes, previous = [], module.advance_lanes, numba.get_num_threads()
    options = {"error_every": 1, **options}

    def counted(*arguments):
        calls.append(arguments[:2])
        return lanes(*arguments)

    with pytest.MonkeyPatch.context() as patch:
        try:
            numba.set_num_threads(min(threads or previous, numba.config.NUMBA_NUM_THREADS))
            patch.setattr(module, "advance_lanes", counted)
            on_lanes = run_batch(scenario, runs, [name], **options)
            patch.setattr(module, "lanes_apply", lambda *arguments: False)
            one_by_one = run_batch(scenario, runs, [name], **options)
        finally:
            numba.set_num_threads(previous)
    return on_lanes, one_by_one, len(calls)


def assert_identical(a, b, name="ekf"):
    if a.error_samples is not None:
        np.testing.assert_array_equal(a.error_samples[name], b.error_samples[name])
    np.testing.assert_array_equal(a.diverged_step[name], b.diverged_step[name])
    for column, values in a.statistics[name].items():
        np.testing.assert_array_equal(values, b.statistics[name][column], err_msg=column)
    for key, values in (a.final or {}).get(name, {}).items():
        np.testing.assert_array_equal(values, b.final[name][key], err_msg=key)


@settings(max_examples=8, deadline=None)
@given(runs=st.integers(1, 40), first_seed=st.integers(0, 2**40),
       pc=st.lists(st.floats(-16.0, -2.0), min_size=1, max_size=3),
       interval=st.sampled_from([0.01, 0.05, 0.2, 1.0]), threads=st.integers(1, 2),
       block_steps=st.sampled_from([7, 100, 2500]), every=st.sampled_from([0, 1, 7]))
def test_the_lanes_kernel_is_the_one_run_kernel_to_the_bit(runs, first_seed, pc, interval,
                                                           threads, block_steps, every):
    # Any batch size (full groups of eight and a remainder, in shares on one
    # or two threads), any block length, per-run Q and tracker intervals
    # (readings due in some lanes only), errors kept at every step, every
    # 7th, or not at all (a campaign's case).
    table = make_runs(SHORT, first_seed + np.arange(runs), pc_exponent=np.resize(pc, runs),
                      time_between_measurements=np.where(np.arange(runs) % 2, interval, 0.2))
    a, b, calls = both_kernels(SHORT, table, threads=threads, block_steps=block_steps,
                               error_every=every)
    assert calls > 0
    assert_identical(a, b)


def test_a_tracker_outage():
    a, b, calls = both_kernels(OUTAGE, make_runs(OUTAGE, np.arange(19)), threads=1)
    assert calls > 0
    assert_identical(a, b)


def test_errors_beyond_120_degrees_take_the_librarys_arccos():
    # Started half a turn off, the first errors are above 120° (arccos of
    # x <= 0.5, which the lanes leave to the library, as common.acos does).
    scenario = SHORT.replace(initial_state=(0.0, 1.0, 0.0, 0.0))
    a, b, calls = both_kernels(scenario, make_runs(scenario, np.arange(17)), threads=1)
    assert calls > 0
    assert (a.error_samples["ekf"][:, 0] > 120.0).all()
    assert_identical(a, b)


def test_a_diverging_lane_beside_healthy_ones():
    # e^709 overflows the covariance within two steps (tests/test_divergence.py).
    pc = np.full(18, SHORT.pc_exponent)
    pc[[2, 9]] = 709.0
    a, b, calls = both_kernels(SHORT, make_runs(SHORT, np.arange(18), pc_exponent=pc),
                               threads=1)
    assert calls > 0
    assert (a.diverged_step["ekf"] >= 0).tolist() == [i in (2, 9) for i in range(18)]
    assert_identical(a, b)


def test_traces_nees_and_health_go_through_the_one_run_kernel():
    class Block:
        has_scale = has_bias = False

    class Record:
        consistency = keep_traces = check_health = False

    class State:
        posterior = end = False

    assert ekf_lanes.lanes_apply(Block, Record, State)
    for owner, field in ((Block, "has_scale"), (Block, "has_bias"), (Record, "keep_traces"),
                         (Record, "consistency"), (Record, "check_health"),
                         (State, "posterior"), (State, "end")):
        setattr(owner, field, True)
        assert not ekf_lanes.lanes_apply(Block, Record, State), field
        setattr(owner, field, False)


def test_a_batch_keeping_traces_takes_the_one_run_kernel():
    _, _, calls = both_kernels(SHORT, make_runs(SHORT, np.arange(9)), keep_traces=True)
    assert calls == 0


# The MEKF's lanes kernel (benchmarks/engine/kernels/mekf_lanes.py).

#: Still, barely turning and a quiet gyro: δq's angle below the series'
#: bound (algebra.SINC_SERIES_BELOW), its sine taken by the series.
STILL = SHORT.replace(initial_rate_radps=(0.0, 0.0, 0.0), gyro_noise=1e-14)


@settings(max_examples=8, deadline=None)
@given(runs=st.integers(1, 40), first_seed=st.integers(0, 2**40),
       interval=st.sampled_from([0.01, 0.05, 0.2, 1.0]), threads=st.integers(1, 2),
       block_steps=st.sampled_from([7, 100, 2500]), every=st.sampled_from([0, 1, 7]),
       options=st.fixed_dictionaries({}, optional={
           "output": st.just("prior"), "gyro_bias_random_walk": st.just(1e-4),
           "gate_probability": st.just(0.99)}),
       fast=st.booleans())
def test_the_mekfs_lanes_kernel_is_its_one_run_kernel_to_the_bit(runs, first_seed, interval,
                                                                 threads, block_steps, every,
                                                                 options, fast):
    # As the EKF's test: any batch size, block length and threads; readings
    # due in some lanes only; errors kept or not. The filter's options: the
    # prior as output, a bias random walk in its model (σ_u², the bias
    # block's growth), readings gated (each lane's own update); and
    # (``fast``) a gyro whose every other run reads some 10-20 rad/s,
    # |ω̂| Δt beyond the series of Φ's coefficients
    # (estimators.mekf.SERIES_BELOW), whose sines and cosines the lanes take
    # (the largest noise a scenario takes: 10 rad/s a sample).
    scenario = SHORT.replace(estimator_options={"mekf": options})
    table = make_runs(scenario, first_seed + np.arange(runs),
                      time_between_measurements=np.where(np.arange(runs) % 2, interval, 0.2),
                      gyro_noise=np.where(np.arange(runs) % 2 & fast, 1.0, SHORT.gyro_noise))
    a, b, calls = both_kernels(scenario, table, threads=threads, name="mekf",
                               block_steps=block_steps, error_every=every)
    assert calls > 0
    assert_identical(a, b, "mekf")


@pytest.mark.parametrize("scenario", [OUTAGE, STILL], ids=["outage", "still"])
def test_the_mekfs_lanes_kernel_with_an_outage_and_at_rest(scenario):
    a, b, calls = both_kernels(scenario, make_runs(scenario, np.arange(19)), threads=1,
                               name="mekf")
    assert calls > 0
    assert_identical(a, b, "mekf")


def test_the_mekfs_errors_beyond_120_degrees_and_diverging_lanes(monkeypatch):
    # Started half a turn off, the prior as output: the first error is above
    # 120°. Two runs' covariances poisoned with an infinity, so that they
    # diverge at their first step.
    from benchmarks.engine.kernels import mekf
    scenario = SHORT.replace(initial_attitude_quat=(0.0, 1.0, 0.0, 0.0),
                             estimator_options={"mekf": {"output": "prior"}})
    made = mekf.initial_state

    def poisoned(estimators):
        state = made(estimators)
        state.P[[2, 9], 0, 0] = np.inf
        return state

    monkeypatch.setattr(mekf, "initial_state", poisoned)
    a, b, calls = both_kernels(scenario, make_runs(scenario, np.arange(18)), threads=1,
                               name="mekf")
    assert calls > 0
    assert (a.diverged_step["mekf"] >= 0).tolist() == [i in (2, 9) for i in range(18)]
    assert (a.error_samples["mekf"][[0, 1, 3], 0] > 120.0).all()
    assert_identical(a, b, "mekf")


def test_what_the_mekfs_lanes_kernel_leaves_to_its_one_run_kernel():
    class Block:
        has_scale = has_bias = False
        vector_available = np.zeros((2, 3, 0), dtype=bool)

    class Record:
        consistency = keep_traces = check_health = False

    class State:
        imu_on = hard_iron = False
        trapezoid = np.zeros(2, dtype=bool)
        gyro_errors = np.zeros((2, 3))

    assert mekf_lanes.lanes_apply(Block, Record, State)
    changes = ((Block, "has_scale", True), (Block, "has_bias", True),
               (Block, "vector_available", np.zeros((2, 3, 1), dtype=bool)),
               (Record, "keep_traces", True), (Record, "consistency", True),
               (Record, "check_health", True), (State, "imu_on", True),
               (State, "hard_iron", True), (State, "trapezoid", np.array([False, True])),
               (State, "gyro_errors", np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1e-6]])))
    for owner, field, value in changes:
        before = getattr(owner, field)
        setattr(owner, field, value)
        assert not mekf_lanes.lanes_apply(Block, Record, State), field
        setattr(owner, field, before)


def test_a_consistency_batch_takes_the_mekfs_one_run_kernel():
    _, _, calls = both_kernels(SHORT, make_runs(SHORT, np.arange(9)), name="mekf",
                               consistency=True)
    assert calls == 0
