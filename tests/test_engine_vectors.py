"""The engine's MEKF and USQUE with vector readings and innovation gating,
held to the per-run filters at 1e-9 at every step; the vector sensors
measured block by block, drawing what one call over the run draws."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from benchmarks import Scenario
from benchmarks.engine.batch import engine_limitation, make_runs, run_batch
from benchmarks.engine.runner import run_many
from benchmarks.metrics import nees
from benchmarks.simulation import (scenario_references, simulate, simulate_truth,
                                   vector_generators)
from dynamics.quaternion import attitude_error_vector_rad
from dynamics.validation import InvalidParameterError

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
VECTOR_FILTERS = ("mekf", "usque")
#: The CubeSat into the Earth's shadow (from 449 s on, where neither sun
#: sensor reads), with a magnetometer bias the filters do not know (the MEKF
#: told not to estimate it): at the scenario's 99.99 % gate, the biased field
#: readings are rejected now and then.
_SHIPPED = Scenario.from_toml(SCENARIOS / "cubesat.toml")
CUBESAT = _SHIPPED.replace(
    tstop=900.0, orbit_argument_of_latitude_deg=82.0, magnetometer_bias_nT=[900.0, -700.0, 500.0],
    estimator_options={**_SHIPPED.estimator_options,
                       "mekf": {**_SHIPPED.estimator_options["mekf"],
                                "magnetometer_bias_states": False}})


def per_run(scenario, name, seed):
    return simulate(scenario, [name], seed=seed, traces=True)


@pytest.fixture(scope="module")
def cubesat_batch():
    runs = make_runs(CUBESAT, [0, 3])
    return runs, run_batch(CUBESAT, runs, VECTOR_FILTERS, keep_traces=True, consistency=True,
                           block_steps=128)


@pytest.mark.parametrize("name", ["mekf", pytest.param("usque", marks=pytest.mark.slow)])
def test_vector_kernels_equal_the_per_run_filters_at_every_step(cubesat_batch, name):
    runs, batch = cubesat_batch
    for i, seed in enumerate(runs.seeds):
        reference = per_run(CUBESAT, name, int(seed))
        trace = reference.traces[name]
        assert trace.rejected.get("magnetometer") is not None      # the gate bites
        assert np.abs(batch.estimates[name][i] - reference.estimates[name]).max() < 1e-9
        # The kernel counts each sensor's rejected readings as the per-run class does.
        sensors = [sensor.name for sensor in CUBESAT.build_vector_sensors()]
        assert list(batch.rejected[name][i]) == [len(trace.rejected.get(sensor, ()))
                                                 for sensor in sensors]
        assert np.allclose(batch.attitude_variances[name][i],
                           np.diagonal(trace.attitude_covariance, axis1=1, axis2=2),
                           rtol=1e-7, atol=0)
        expected = nees(attitude_error_vector_rad(reference.truth.q_true, trace.quat),
                        trace.attitude_covariance)
        assert batch.consistency[name]["nees_time_average"][i] == pytest.approx(
            expected.mean(), rel=1e-6)


def test_no_star_tracker_means_no_nis_rather_than_zero(cubesat_batch):
    _, batch = cubesat_batch
    for name in VECTOR_FILTERS:
        assert np.all(np.isnan(batch.consistency[name]["nis_mean"]))


def test_a_vector_run_is_bit_identical_whatever_its_batch_and_blocks(cubesat_batch):
    runs, batch = cubesat_batch
    alone = run_batch(CUBESAT, runs.take([1]), VECTOR_FILTERS, keep_traces=True,
                      block_steps=1000)
    for name in VECTOR_FILTERS:
        assert np.array_equal(alone.estimates[name][0], batch.estimates[name][1])


def test_vector_runs_that_share_a_seed_read_what_each_reads_alone():
    # Runs of one seed share their vector readings (made once, copied); a
    # run whose gyro differs still reads its own seed's, as it would alone.
    scenario = CUBESAT.replace(tstop=60.0)
    runs = make_runs(scenario, [3, 8, 3, 3], gyro_noise=[1e-10, 1e-10, 4e-10, 1e-10])
    batch = run_batch(scenario, runs, ["mekf"], keep_traces=True, block_steps=250)
    for i in range(len(runs)):
        alone = run_batch(scenario, runs.take([i]), ["mekf"], keep_traces=True,
                          block_steps=250)
        assert np.array_equal(alone.estimates["mekf"][0], batch.estimates["mekf"][i]), i
        assert np.array_equal(alone.rejected["mekf"][0], batch.rejected["mekf"][i]), i


def test_vector_and_workshop_batches_share_one_compiled_kernel(cubesat_batch):
    # The vector arrays have the same types with sensors and without (S = 0):
    # a vector scenario costs no second compile (about 40 s, cold).
    from benchmarks.engine.kernels import kernel
    run_batch(Scenario(tstop=1.0), make_runs(Scenario(), [0]), VECTOR_FILTERS)
    for name in VECTOR_FILTERS:
        assert len(kernel(name).advance_runs.signatures) == 1


@pytest.mark.parametrize("name", VECTOR_FILTERS)
def test_from_a_large_initial_error_the_kernels_follow_the_per_run_filters(name):
    # Magnetometer only, 176° off: the filters' first hours are far from
    # linear, where any difference would grow. It does not here.
    scenario = Scenario.from_toml(SCENARIOS / "magnetometer_only.toml").replace(tstop=7200.0)
    batch = run_batch(scenario, make_runs(scenario, [1]), [name], keep_traces=True)
    reference = per_run(scenario, name, 1)
    assert np.abs(batch.estimates[name][0] - reference.estimates[name]).max() < 1e-9


@pytest.mark.parametrize("name", VECTOR_FILTERS)
def test_gated_star_tracker_readings_are_rejected_as_the_per_run_class_rejects_them(name):
    # A 50 % gate rejects most of the readings here, and applies some: the
    # two paths must agree on every one of them.
    scenario = Scenario.from_toml(SCENARIOS / "smallsat.toml").replace(
        tstop=120.0, estimator_options={name: {"gate_probability": 0.5}})
    batch = run_batch(scenario, make_runs(scenario, [2]), [name], keep_traces=True,
                      consistency=True)
    reference = per_run(scenario, name, 2)
    trace = reference.traces[name]
    readings = reference.sensors.available.sum()
    assert 0 < len(trace.rejected["star_tracker"]) < readings
    assert np.abs(batch.estimates[name][0] - reference.estimates[name]).max() < 1e-9
    assert batch.consistency[name]["nis_mean"][0] == pytest.approx(np.nanmean(trace.nis),
                                                                   rel=1e-6)


def test_the_ekf_takes_the_per_run_path_beside_the_engines_mekf():
    scenario = CUBESAT.replace(tstop=60.0)
    assert engine_limitation(scenario, name="mekf") is None
    assert engine_limitation(scenario, name="dead-reckoning") is None
    assert "vector sensors" in engine_limitation(scenario, name="ekf")
    gated = Scenario().replace(estimator_options={"ekf": {"gate_probability": 0.99}})
    assert "gating" in engine_limitation(gated, name="ekf")
    with pytest.raises(InvalidParameterError, match="vector sensors"):
        run_batch(scenario, make_runs(scenario, [0]), ["ekf"])
    with pytest.warns(UserWarning, match="ekf takes the per-run path") as caught:
        batch = run_many(scenario, make_runs(scenario, [0, 1]), ["ekf", "mekf"])
    assert not any("mekf takes" in str(w.message) for w in caught)
    for name in ("ekf", "mekf"):
        result = simulate(scenario, [name], seed=1)
        assert batch.statistics[name]["rms_deg"][1] == pytest.approx(
            np.sqrt(np.mean(result.error_deg[name] ** 2)), rel=1e-9)


@settings(max_examples=25, deadline=None)
@given(cuts=st.lists(st.integers(1, 299), max_size=4, unique=True), seed=st.integers(0, 2**31))
def test_block_by_block_vector_readings_are_the_whole_runs(cuts, seed):
    """For any split of a run into blocks, each sensor's readings block by
    block (``first_step``) are its readings of the whole run, bit for bit."""
    scenario = CUBESAT.replace(tstop=299.0, magnetometer_interval_s=3.0,
                               coarse_sun_interval_s=2.0)
    q_true = simulate_truth(scenario).q_true
    references = scenario_references(scenario)
    from benchmarks.engine.vectors import references_between
    sensors = scenario.build_vector_sensors()
    whole = [sensor.measure(q_true, references, rng)
             for sensor, rng in zip(sensors, vector_generators(seed, len(sensors)))]
    edges = [0, *sorted(cuts), len(q_true)]
    streams = vector_generators(seed, len(sensors))
    for start, stop in zip(edges, edges[1:]):
        part = references_between(references, start, stop)
        for sensor, rng, full in zip(sensors, streams, whole):
            block = sensor.measure(q_true[start:stop], part, rng, first_step=start)
            for field in ("body", "reference", "available", "variance"):
                assert np.array_equal(getattr(block, field), getattr(full, field)[start:stop])


@settings(max_examples=10, deadline=None)
@given(n_runs=st.integers(1, 7), parts=st.integers(1, 4), seed=st.integers(0, 2**31))
def test_vector_readings_made_in_parts_are_those_made_at_once(n_runs, parts, seed):
    """The engine makes a block's vector readings in parts of the runs, in
    threads (vector_block with a pool): every array is the one made for all
    the runs at once, bit for bit, however the runs are parted."""
    from concurrent.futures import ThreadPoolExecutor
    from benchmarks.engine.vectors import vector_block, vector_streams
    scenario = CUBESAT.replace(tstop=120.0)
    q_true = simulate_truth(scenario).q_true
    seeds = seed + np.arange(n_runs)
    at_once = vector_block(vector_streams(scenario, seeds), n_runs, 0, q_true)
    with ThreadPoolExecutor(max_workers=2) as pool:
        in_parts = vector_block(vector_streams(scenario, seeds), n_runs, 0, q_true, pool,
                                parts).result()
    assert set(in_parts) == set(at_once)
    for name, values in at_once.items():
        assert np.array_equal(in_parts[name], values), name


def test_a_part_of_the_readings_that_fails_raises_its_error():
    """A sensor failing on one part of the runs: the block's future raises
    that error (the other part still runs to its end, awaited by the
    executor as run_batch's ``with`` awaits it)."""
    from concurrent.futures import ThreadPoolExecutor
    from dataclasses import replace as replaced
    from benchmarks.engine.vectors import vector_block, vector_streams
    scenario = CUBESAT.replace(tstop=30.0)
    q_true = simulate_truth(scenario).q_true
    streams = vector_streams(scenario, np.arange(4))
    first_generator, finished = streams.generators[0][0], []

    class Failing:
        def __init__(self, sensor):
            self.sensor, self.name, self.dof = sensor, sensor.name, sensor.dof

        def measure_into(self, q, references, rngs, first_step, *arrays):
            if rngs[0] is first_generator:
                raise ValueError("part 0 failed")
            reference = self.sensor.measure_into(q, references, rngs, first_step, *arrays)
            finished.append(len(rngs))
            return reference

    failing = replaced(streams, sensors=(Failing(streams.sensors[0]), *streams.sensors[1:]))
    with ThreadPoolExecutor(max_workers=2) as pool:
        future = vector_block(failing, 4, 0, q_true, pool, 2)
        with pytest.raises(ValueError, match="part 0 failed"):
            future.result()
    assert finished == [2]       # the other part, two runs, measured to its end
