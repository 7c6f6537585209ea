"""The EKF's lanes kernel (eight runs side by side in vector instructions)
against its one-run kernel: the same numbers to the bit, step by step, in
every case it covers (benchmarks/engine/kernels/ekf_lanes.py)."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks import Scenario
from benchmarks.engine import make_runs, run_batch
from benchmarks.engine.kernels import ekf_lanes

SHORT = Scenario(tstop=3.0)
#: The tracker silent for half a second.
OUTAGE = SHORT.replace(star_tracker_outages_s=((1.0, 1.5),))


def both_kernels(scenario, runs, threads=None, **options):
    """The EKF's batch on the lanes kernel, then on the one-run kernel (each
    error kept at every step unless ``error_every`` says otherwise), on
    ``threads`` of numba's (default: as many as it has); and how many shares
    the lanes kernel took."""
    import numba
    calls, lanes, previous = [], ekf_lanes.advance_lanes, numba.get_num_threads()
    options = {"error_every": 1, **options}

    def counted(*arguments):
        calls.append(arguments[:2])
        return lanes(*arguments)

    with pytest.MonkeyPatch.context() as patch:
        try:
            numba.set_num_threads(min(threads or previous, numba.config.NUMBA_NUM_THREADS))
            patch.setattr(ekf_lanes, "advance_lanes", counted)
            on_lanes = run_batch(scenario, runs, ["ekf"], **options)
            patch.setattr(ekf_lanes, "lanes_apply", lambda *arguments: False)
            one_by_one = run_batch(scenario, runs, ["ekf"], **options)
        finally:
            numba.set_num_threads(previous)
    return on_lanes, one_by_one, len(calls)


def assert_identical(a, b):
    if a.error_samples is not None:
        np.testing.assert_array_equal(a.error_samples["ekf"], b.error_samples["ekf"])
    np.testing.assert_array_equal(a.diverged_step["ekf"], b.diverged_step["ekf"])
    for column, values in a.statistics["ekf"].items():
        np.testing.assert_array_equal(values, b.statistics["ekf"][column], err_msg=column)


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
