"""Inputs that used to end in a traceback or a silent surprise: each now gets
one clear line (issue 9's "What was seen")."""
import importlib
import pickle
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from benchmarks import Scenario
from benchmarks.cli import main
from benchmarks.engine import make_runs
from dynamics.validation import InvalidParameterError
from estimators import QuaternionEKF


@pytest.mark.parametrize("build", [
    lambda: Scenario(pc_exponent=710.0),
    lambda: QuaternionEKF(pc_exponent=1e4),
    lambda: make_runs(Scenario(), [0], pc_exponent=[800.0]),
])
def test_pc_exponent_too_large_is_a_value_error_not_an_overflow(build):
    with pytest.raises(InvalidParameterError, match="pc_exponent = .*must be <= 709"):
        build()


def test_pc_exponent_too_large_from_the_command_line_and_a_file(tmp_path, capsys):
    assert main(["compare", "--pc-exponent", "710", "--out", str(tmp_path / "a")]) == 2
    assert "pc_exponent = 710.0: must be <= 709" in capsys.readouterr().err
    scenario = tmp_path / "s.toml"
    scenario.write_text("pc_exponent = 1000.0\n")
    assert main(["compare", "--scenario", str(scenario), "--out", str(tmp_path / "b")]) == 2
    # named as the files name it, the field after it (one name from file to flag)
    assert "estimators.ekf.pc_exponent (pc_exponent) = 1000.0" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("seeds", [[1.7], [-1], [2 ** 63], ["one"], [True]])
def test_make_runs_refuses_seeds_that_are_not_int64_whole_numbers(seeds):
    with pytest.raises(InvalidParameterError, match="seed"):
        make_runs(Scenario(tstop=1.0), seeds)


@pytest.mark.parametrize("argv, text", [
    (["tune", "--seeds", "9223372036854775808"], "at most 2^63 - 1"),
    (["montecarlo", "--seed", "9223372036854775807", "--runs", "3"], "would pass 2^63 - 1"),
    (["montecarlo", "--seed", "9223372036854775808"], "from 0 to 9223372036854775807"),
    (["montecarlo", "--estimators", "ekf,ekf"], "names ekf more than once"),
    (["compare", "--estimators", "mekf,ekf,mekf"], "names mekf more than once"),
])
def test_seed_and_estimator_lists_refused_before_anything_is_written(tmp_path, capsys, argv,
                                                                     text):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert text in err and "Traceback" not in err and err.count("\n") == 1
    assert not out.exists()


def test_largest_seed_still_runs():
    runs = make_runs(Scenario(tstop=1.0), [2 ** 63 - 1])
    assert runs.seeds.dtype == np.int64 and runs.seeds[0] == 2 ** 63 - 1


def test_output_folder_is_checked_before_any_work(tmp_path, capsys):
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    assert main(["compare", "--out", str(a_file)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    assert main(["compare", "--out", str(a_file / "below")]) == 2
    assert "cannot be created" in capsys.readouterr().err
    (tmp_path / "o" / "summary.csv").mkdir(parents=True)
    assert main(["compare", "--out", str(tmp_path / "o")]) == 2
    assert "holds a folder named summary.csv" in capsys.readouterr().err
    assert a_file.read_text() == "keep me"
    assert list((tmp_path / "o").iterdir()) == [tmp_path / "o" / "summary.csv"]


def test_a_run_that_cannot_fit_in_memory_is_refused_naming_tstop(tmp_path, capsys):
    scenario = tmp_path / "s.toml"
    scenario.write_text("tstop = 1e12\n")      # 1e14 steps: past any machine
    for command in ("compare", "montecarlo", "landscape"):
        assert main([command, "--scenario", str(scenario), "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("attitude-bench: error: tstop = 1000000000000.0: makes "
                              "100,000,000,000,000 steps")
        assert "at most 10,000,000,000 steps" in err and err.count("\n") == 1
    # 1e9 steps: the per-run path keeps ~240 bytes a step (240 GB), the engine is flat.
    scenario.write_text("tstop = 1e7\n")
    for command in ("compare", "landscape"):
        assert main([command, "--scenario", str(scenario), "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("attitude-bench: error: tstop = 10000000.0: needs about")
        assert "at most about tstop" in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_the_engine_commands_memory_does_not_grow_with_the_run():
    from benchmarks.cli import build_parser
    from benchmarks.commands import command
    from benchmarks.resources import engine_bytes
    assert engine_bytes(10**9) == engine_bytes(10**7) < 2**30
    args = build_parser().parse_args(["montecarlo"])
    command("montecarlo").memory(args, Scenario(tstop=1e7))     # 1e9 steps: accepted


def test_memory_check_suggests_the_streaming_engine_where_it_fits():
    from benchmarks.resources import check_memory, engine_bytes, per_run_bytes
    scenario = Scenario(tstop=1e5)       # 1e7 steps: ~10 GB per run, ~0.2 GB streamed
    need = per_run_bytes(scenario.n_steps, 3, traced=True)
    with pytest.raises(InvalidParameterError, match="streaming engine .*montecarlo"):
        check_memory(scenario, need, streaming_bytes=engine_bytes(scenario.n_steps),
                     limit_bytes=need // 2)
    check_memory(scenario, need, limit_bytes=need)          # exactly fits: accepted


def test_huge_quaternions_normalise_and_huge_rates_are_refused():
    q = Scenario(initial_attitude_quat=[1e300, 1e300, 0, 0]).initial_attitude_quat
    assert np.allclose(q, [2 ** -0.5, 2 ** -0.5, 0, 0], atol=1e-15)
    with pytest.raises(InvalidParameterError, match="initial_rate_radps = .*within"):
        Scenario(initial_rate_radps=[1e300, 0, 0])


def test_workshop_checks_every_activity_before_writing(tmp_path, capsys):
    out = tmp_path / "w"
    # A 0.3 s gyro step: Activity 2's 0.2 s tracker would read twice in some steps.
    assert main(["workshop", "--dt", "0.3", "--time-between-measurements", "0.3",
                 "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "interval_s (time_between_measurements) = 0.2" in err and "step 5" in err
    assert not out.exists()


def test_sweep_refuses_repeated_values_and_labels_every_interval_apart(tmp_path, capsys):
    from benchmarks.experiments import SWEEP_PARAMETERS
    assert main(["sweep", "--estimator", "dead-reckoning-resets", "--param",
                 "time-between-measurements", "--values", "0.2,1,0.2", "--out",
                 str(tmp_path / "s")]) == 2
    assert "names 0.2 more than once" in capsys.readouterr().err
    legend = SWEEP_PARAMETERS["time-between-measurements"].legend
    labels = {legend.format(value=v, label="") for v in (0.01, 0.04, 0.05)}
    assert len(labels) == 3


def campaign_folder(tmp_path):
    out = tmp_path / "c"
    assert main(["montecarlo", "--runs", "6", "--chunk-size", "3", "--tstop", "1", "--out",
                 str(out), "--quiet"]) == 0
    return out


def test_resume_recomputes_a_damaged_chunk(tmp_path, capsys):
    out = campaign_folder(tmp_path)
    before = (out / "montecarlo.csv").read_text()
    chunk = sorted((out / "chunks").iterdir())[1]
    chunk.write_bytes(chunk.read_bytes()[:40])          # a truncated copy
    assert main(["montecarlo", "--runs", "6", "--chunk-size", "3", "--tstop", "1", "--out",
                 str(out), "--quiet", "--resume"]) == 0
    assert (out / "montecarlo.csv").read_text() == before


def test_resume_refuses_a_damaged_manifest(tmp_path, capsys):
    out = campaign_folder(tmp_path)
    (out / "campaign.json").write_text("{not json")
    capsys.readouterr()
    assert main(["montecarlo", "--runs", "6", "--chunk-size", "3", "--tstop", "1", "--out",
                 str(out), "--quiet", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "campaign.json is damaged" in err and "Traceback" not in err


@pytest.mark.slow
def test_bad_or_unreachable_scheduler_leaves_nothing(tmp_path, capsys, monkeypatch):
    from benchmarks.engine import runner
    out = tmp_path / "c"
    assert main(["montecarlo", "--scheduler", "not-an-address", "--out", str(out)]) == 2
    assert "scheduler = 'not-an-address'" in capsys.readouterr().err
    monkeypatch.setattr(runner, "SCHEDULER_TIMEOUT_S", 2)
    assert main(["montecarlo", "--scheduler", "tcp://127.0.0.1:9", "--tstop", "1",
                 "--out", str(out), "--quiet"]) == 2
    assert "cannot be reached" in capsys.readouterr().err
    assert not (out / "campaign.json").exists()


def test_fine_landscape_grids_animate_a_capped_number_of_frames():
    from benchmarks.experiments.landscape import MAX_ANIMATION_FRAMES, animation_indices, pc_grid
    grid = pc_grid(-18, 0, 0.0025)                        # 7201 values, allowed
    indices = animation_indices(len(grid))
    assert len(indices) == MAX_ANIMATION_FRAMES
    assert indices[0] == 0 and indices[-1] == len(grid) - 1 and np.all(np.diff(indices) > 0)
    assert np.array_equal(animation_indices(73), np.arange(73))


@pytest.mark.parametrize("command", ["tune", "landscape"])
def test_tune_and_landscape_refuse_a_pc_exponent_they_would_ignore(tmp_path, capsys, command):
    assert main([command, "--pc-exponent", "-9", "--out", str(tmp_path / "x")]) == 2
    assert "chooses pc_exponent itself" in capsys.readouterr().err


@pytest.mark.parametrize("content, name", [
    ("[star_tracker]\ndropout_probability = 1.0\n", "star_tracker_dropout_probability"),
    ("[star_tracker]\nsigma_arcsec = [1, -1, 2]\n", "star_tracker_sigma_arcsec"),
])
def test_rotation_tracker_settings_are_checked_whatever_the_model(tmp_path, capsys, content,
                                                                  name):
    path = tmp_path / "s.toml"
    path.write_text(content)           # the model stays the workshop's
    assert main(["compare", "--scenario", str(path), "--out", str(tmp_path / "x")]) == 2
    key = name.replace("star_tracker_", "star_tracker.", 1)
    assert capsys.readouterr().err.startswith(f"attitude-bench: error: {key} ({name}) = ")


@pytest.mark.parametrize("module, name", [("dynamics.validation", "InvalidParameterError"),
                                          ("estimators.readings", "InvalidMeasurementError"),
                                          ("estimators.stepping", "InvalidEstimateError")])
def test_a_refusal_raised_in_another_process_reaches_the_caller_as_itself(module, name):
    # A campaign's worker (a process pool's, a Dask cluster's) sends its
    # exception back pickled: before, unpickling failed (the constructor
    # takes three parts) and the caller saw a broken pool, not the line.
    cls = getattr(importlib.import_module(module), name)
    error = cls("gyro.arw_deg_per_rthr", -1.0, "must be >= 0")
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is cls
    assert str(copy) == str(error) == "gyro.arw_deg_per_rthr = -1.0: must be >= 0"
    assert (copy.name, copy.value, copy.rule) == (error.name, error.value, error.rule)
    with ProcessPoolExecutor(max_workers=1) as pool:
        with pytest.raises(InvalidParameterError, match=r"^seed = -1: must be a whole number"):
            pool.submit(make_runs, Scenario(), [-1]).result()
