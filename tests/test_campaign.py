"""Monte Carlo campaigns: chunking, Dask, crash and resume, bad input."""
import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from benchmarks import Scenario
from benchmarks.cli import main
from benchmarks.engine import make_runs, run_batch
from benchmarks.engine.campaign import CHUNKS, Campaign, load_campaign, run_campaign
from benchmarks.metrics import STAT_COLUMNS

SCENARIO = Scenario(tstop=10.0)
ESTIMATORS = ("dead-reckoning", "dead-reckoning-resets", "ekf")


def direct_frame(n_runs, base_seed=0, scenario=SCENARIO):
    """The same runs computed in one engine batch, as the campaign's tidy frame."""
    batch = run_batch(scenario, make_runs(scenario, np.arange(base_seed, base_seed + n_runs)),
                      ESTIMATORS)
    return batch.frame()[["run", "seed", "estimator", *STAT_COLUMNS, "diverged_step"]]


def test_campaign_equals_one_batch_whatever_the_chunk_size(tmp_path):
    expected = direct_frame(37, base_seed=5)
    for chunk in (37, 10, 1):
        campaign = Campaign(SCENARIO, ESTIMATORS, runs=37, base_seed=5, chunk_runs=chunk)
        frame = run_campaign(campaign, tmp_path / f"c{chunk}")
        pd.testing.assert_frame_equal(frame, expected, check_exact=True)
        assert len(list((tmp_path / f"c{chunk}" / CHUNKS).iterdir())) == -(-37 // chunk)


@pytest.mark.slow
def test_two_worker_dask_cluster_gives_identical_results(tmp_path):
    pytest.importorskip("distributed")
    campaign = Campaign(SCENARIO, ESTIMATORS, runs=24, base_seed=100, chunk_runs=5)
    in_process = run_campaign(campaign, tmp_path / "local")
    on_dask = run_campaign(campaign, tmp_path / "dask", workers=2)
    pd.testing.assert_frame_equal(on_dask, in_process, check_exact=True)


def _worker_environ(name):
    return os.environ.get(name)


@pytest.mark.slow
def test_a_local_clusters_workers_map_only_large_allocations():
    # Dask's own worker settings stay (MALLOC_TRIM_THRESHOLD_, one BLAS
    # thread); the mapping threshold they would freeze at 128 kB is raised
    # (runner.WORKER_MMAP_THRESHOLD: the arithmetic, and so the results, the same).
    pytest.importorskip("distributed")
    from benchmarks.engine.runner import WORKER_MMAP_THRESHOLD, dask_client
    client, cluster = dask_client(1, None)
    try:
        for name, value in (("MALLOC_MMAP_THRESHOLD_", str(WORKER_MMAP_THRESHOLD)),
                            ("MALLOC_TRIM_THRESHOLD_", "65536"),
                            ("OPENBLAS_NUM_THREADS", "1")):
            assert set(client.run(_worker_environ, name).values()) == {value}
    finally:
        client.close()
        cluster.close()


@pytest.mark.slow
def test_killed_campaign_resumes_without_redoing_chunks(tmp_path):
    out = tmp_path / "campaign"
    argv = ["montecarlo", "--runs", "400", "--chunk-size", "8", "--seed", "3",
            "--out", str(out), "--quiet"]
    # From another folder, on the source tree's package, whose kernels the
    # suite has compiled (an installed copy would compile them again: a minute).
    source = str(Path(__file__).resolve().parents[1])
    environment = {**os.environ,
                   "PYTHONPATH": os.pathsep.join(filter(None, [source,
                                                               os.environ.get("PYTHONPATH")]))}
    process = subprocess.Popen([sys.executable, "-m", "benchmarks", *argv], cwd=tmp_path,
                               env=environment, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    chunks = out / CHUNKS
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and process.poll() is None:
        if chunks.exists() and any(p.suffix == ".npz" for p in chunks.iterdir()):
            break
        time.sleep(0.002)
    process.send_signal(signal.SIGKILL)      # a crash, not a polite stop
    process.wait()
    finished = {p.name: p.stat().st_mtime_ns for p in chunks.iterdir() if p.suffix == ".npz"}
    assert 1 <= len(finished) < 50, "the campaign should have been killed part-way"

    assert main([*argv, "--resume"]) == 0
    after = {p.name: p.stat().st_mtime_ns for p in chunks.iterdir()}
    assert len(after) == 50 and not [name for name in after if name.startswith(".")]
    for name, mtime in finished.items():
        assert after[name] == mtime, f"{name} was computed again"
    with open(out / "montecarlo.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 3 * 400
    frame = pd.DataFrame(rows)
    expected = direct_frame(400, base_seed=3, scenario=Scenario())
    for column in STAT_COLUMNS:
        assert np.array_equal(frame[column].astype(float).to_numpy(),
                              expected[column].to_numpy())    # 17 digits round-trip
    assert frame["seed"].astype(int).tolist() == expected["seed"].tolist()


def test_montecarlo_cli_outputs(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["montecarlo", "--estimators", "ekf,dead-reckoning", "--runs", "12",
                 "--seed", "7", "--tstop", "5", "--out", str(out), "--quiet"]) == 0
    with open(out / "montecarlo.csv", newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["run", "seed", "estimator", *STAT_COLUMNS, "diverged_step"]
    assert [r[2] for r in rows[1:]] == ["ekf"] * 12 + ["dead-reckoning"] * 12   # as asked
    assert {r[-1] for r in rows[1:]} == {"-1"}                                  # none diverged
    assert [int(r[1]) for r in rows[1:13]] == list(range(7, 19))
    assert (out / "montecarlo.png").stat().st_size > 20_000
    printed = capsys.readouterr().out
    assert "mean over 12 runs" in printed and "ekf: error std over runs 5%" in printed


@pytest.mark.parametrize("argv, text", [
    (["--estimators", "ekf,ukf"], "estimators"),
    (["--runs", "0"], "runs"),
    (["--chunk-size", "-2"], "chunk-size"),
    (["--workers", "0"], "workers"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    (["--resume"], "resume"),
])
def test_bad_montecarlo_input_fails_cleanly(tmp_path, capsys, argv, text):
    out = tmp_path / "out"
    assert main(["montecarlo", "--out", str(out), "--tstop", "1", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert text in err and len(err.splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_existing_campaign_needs_resume_and_same_settings(tmp_path, capsys):
    out = tmp_path / "mc"
    base = ["montecarlo", "--runs", "4", "--tstop", "1", "--out", str(out), "--quiet"]
    assert main(base) == 0
    capsys.readouterr()
    assert main(base) == 2
    assert "--resume" in capsys.readouterr().err
    assert main([*base[:2], "5", *base[3:], "--resume"]) == 2
    assert "runs = 4" in capsys.readouterr().err
    assert main([*base, "--resume"]) == 0     # nothing left to do: reassembles


def test_chunks_cover_the_runs_and_missing_chunks_are_not_invented(tmp_path):
    campaign = Campaign(SCENARIO, ("ekf",), runs=3, chunk_runs=2)
    assert campaign.chunks() == [(0, 2), (2, 3)]
    with pytest.raises(FileNotFoundError):
        load_campaign(campaign, tmp_path)
