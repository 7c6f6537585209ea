"""Monte Carlo campaigns: many runs, in chunks, in-process or on a Dask cluster.

Run ``i`` of a campaign with base seed ``S`` uses seed ``S + i``, so its
numbers depend on those two alone, never on the chunk size or on which
worker computed it. Each finished chunk is written to ``DIR/chunks/`` at
once (write to a temporary file, then rename), and ``DIR/campaign.json``
records the campaign's settings; ``resume=True`` finishes an interrupted
campaign by computing only the chunks whose files are missing.

Dask is optional (``pip install .[distributed]``): ``workers=N`` starts a
local cluster of N single-threaded worker processes, ``scheduler=ADDRESS``
uses an existing cluster. Chunk results travel back to this process, which
writes them, so workers need no access to the output folder.
"""
from __future__ import annotations

import hashlib
import io
import json
import dataclasses
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.engine.batch import CHUNK_RUNS, ENGINE_ESTIMATORS, make_runs, seed_range
from benchmarks.engine.runner import dask_client, run_many
from benchmarks.metrics import STAT_COLUMNS
from benchmarks.output import write_bytes, write_text
from benchmarks.scenario import Scenario
from benchmarks.sensor_use import Usage
from dynamics.validation import InvalidParameterError

MANIFEST = "campaign.json"
CHUNKS = "chunks"
#: A chunk's columns per estimator: the statistics (NaN for a diverged run)
#: and the step where the run diverged (-1: it did not).
CHUNK_COLUMNS = STAT_COLUMNS + ("diverged_step",)
CAMPAIGN_COLUMNS = ("run", "seed", "estimator") + CHUNK_COLUMNS
_FORMAT = 2


@dataclass(frozen=True)
class Campaign:
    """What a campaign computes: ``runs`` runs of ``estimators`` from ``base_seed``."""

    scenario: Scenario
    estimators: tuple
    runs: int
    base_seed: int = 0
    chunk_runs: int = CHUNK_RUNS

    def manifest(self) -> dict:
        return {"format": _FORMAT, "scenario": self.scenario.as_dict(),
                "estimators": list(self.estimators), "runs": self.runs,
                "base_seed": self.base_seed, "chunk_runs": self.chunk_runs}

    def fingerprint(self) -> str:
        """A digest of what decides a run's numbers: the scenario, the
        estimators and the base seed. Every chunk carries it, so ``--resume``
        can tell a chunk of this campaign from one copied from another."""
        decisive = {"format": _FORMAT, "scenario": self.scenario.as_dict(),
                    "estimators": list(self.estimators), "base_seed": self.base_seed}
        text = json.dumps(decisive, sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()

    def chunks(self) -> list[tuple[int, int]]:
        return [(start, min(start + self.chunk_runs, self.runs))
                for start in range(0, self.runs, self.chunk_runs)]


def chunk_path(out: Path, start: int, stop: int) -> Path:
    return Path(out) / CHUNKS / f"runs-{start:09d}-{stop:09d}.npz"


def compute_chunk(scenario: Scenario, estimators, base_seed: int, start: int, stop: int,
                  threads: int | None = None) -> dict:
    """Statistics of runs ``start … stop-1``: ``{"seed": …, "NAME/COLUMN": …}``.

    Runs on Dask workers too; ``threads`` caps the kernel's threads there so
    that worker processes do not oversubscribe the cores. The estimators
    run as :func:`~benchmarks.engine.runner.run_many` runs them.
    """
    if threads is not None:
        import numba
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    runs = make_runs(scenario, seed_range(base_seed + start, stop - start))
    batch = run_many(scenario, runs, estimators, threads=threads)
    arrays = {"seed": runs.seeds}
    for name in estimators:
        for column in STAT_COLUMNS:
            arrays[f"{name}/{column}"] = batch.statistics[name][column]
        arrays[f"{name}/diverged_step"] = batch.diverged_step[name]
        # What its runs made of their readings, as text (a chunk holds no pickles).
        arrays[f"{name}/usage"] = np.array(json.dumps(dataclasses.asdict(batch.usage[name])))
    return arrays


def _write_chunk(out: Path, start: int, stop: int, arrays: dict) -> None:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    write_bytes(chunk_path(out, start, stop), buffer.getvalue())


def check_campaign_out(campaign: Campaign, out: Path, resume: bool) -> None:
    """Refuse, writing nothing, what :func:`run_campaign` would refuse of
    ``out``: a campaign there without ``resume``, none there with it, or
    one made with other settings (so a command can check before work that
    writes files of its own, such as ``--tuned``'s)."""
    manifest_path = Path(out) / MANIFEST
    expected = campaign.manifest()
    check_campaign_folder(out, resume)
    if manifest_path.exists():
        try:
            found = json.loads(manifest_path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InvalidParameterError(
                "resume", str(out), f"its {MANIFEST} is damaged ({err}); remove the folder "
                "or choose another --out") from None
        if not isinstance(found, dict):
            raise InvalidParameterError("resume", str(out), f"its {MANIFEST} is damaged (not "
                                        "an object); remove the folder or choose another --out")
        for key in expected:
            if found.get(key) != expected[key]:
                raise InvalidParameterError(
                    "resume", str(out), f"the campaign there has {key} = {found.get(key)!r}, "
                    f"not {expected[key]!r}; resume it with its own settings")


def check_campaign_folder(out: Path, resume: bool) -> None:
    """Refuse a folder holding a campaign without ``resume``, or none with it."""
    if (Path(out) / MANIFEST).exists():
        if not resume:
            raise InvalidParameterError(
                "out", str(out), "already holds a campaign; pass --resume to finish it "
                "or choose another --out")
    elif resume:
        raise InvalidParameterError("resume", str(out), "holds no campaign to resume")


def _prepare(campaign: Campaign, out: Path, resume: bool) -> bool:
    """Check or write ``campaign.json``; True if this call wrote it."""
    manifest_path = out / MANIFEST
    manifest_existed = manifest_path.exists()
    check_campaign_out(campaign, out, resume)
    if not manifest_existed:
        write_text(manifest_path, json.dumps(campaign.manifest(), indent=2) + "\n")
    # A crash can leave a temporary file beside the chunks: never a result.
    for stale in (out / CHUNKS).glob(".*.tmp*"):
        stale.unlink(missing_ok=True)
    return not manifest_existed


def check_campaign(campaign: Campaign) -> None:
    """Refuse a campaign that cannot run, before anything is written: its
    counts, and every estimator built from the scenario as a run builds it."""
    from benchmarks.engine.batch import checked_estimators, whole_number
    from benchmarks.simulation import build_estimator
    whole_number("runs", campaign.runs, 1)
    whole_number("chunk_runs", campaign.chunk_runs, 1)
    whole_number("base_seed", campaign.base_seed, 0)
    if isinstance(campaign.estimators, str) or not campaign.estimators:
        raise InvalidParameterError("estimators", campaign.estimators,
                                    "must be a non-empty list of names")
    engine = [name for name in campaign.estimators if name in ENGINE_ESTIMATORS]
    if engine:
        checked_estimators(engine)
    make_runs(campaign.scenario, seed_range(campaign.base_seed, 1))
    for name in campaign.estimators:
        build_estimator(name, campaign.scenario)


def run_campaign(campaign: Campaign, out, workers: int = 0, scheduler: str | None = None,
                 resume: bool = False, progress_bar=None) -> pd.DataFrame:
    """Compute every missing chunk, then return the tidy per-run statistics."""
    out = Path(out)
    check_campaign(campaign)
    # Connect first: a scheduler that cannot be reached leaves nothing behind.
    remote = workers or scheduler is not None
    client, cluster = dask_client(workers, scheduler) if remote else (None, None)
    try:
        fresh = _prepare(campaign, out, resume)
        todo = [(start, stop) for start, stop in campaign.chunks()
                if not _chunk_ok(campaign, chunk_path(out, start, stop), stop - start)]
    except BaseException:
        _close(client, cluster)
        raise
    if progress_bar is not None:
        progress_bar.update(campaign.runs - sum(stop - start for start, stop in todo))
    try:
        _compute(campaign, out, todo, client, cluster, progress_bar)
    except Exception:
        if fresh and not any((out / CHUNKS).glob("runs-*.npz")):
            (out / MANIFEST).unlink(missing_ok=True)     # a refused campaign leaves nothing
        raise
    return load_campaign(campaign, out)


def _compute(campaign: Campaign, out: Path, todo, client, cluster, progress_bar) -> None:
    """Compute the chunks ``todo``, writing each as it arrives."""
    arguments = (campaign.scenario, campaign.estimators, campaign.base_seed)
    fingerprint = {"fingerprint": np.array(campaign.fingerprint())}
    if client is not None:
        try:
            from distributed import as_completed
            futures = {client.submit(compute_chunk, *arguments, start, stop, 1, pure=False):
                       (start, stop) for start, stop in todo}
            for future in as_completed(futures):
                start, stop = futures[future]
                _write_chunk(out, start, stop, {**future.result(), **fingerprint})
                if progress_bar is not None:
                    progress_bar.update(stop - start)
        finally:
            _close(client, cluster)
    else:
        for start, stop in todo:
            _write_chunk(out, start, stop, {**compute_chunk(*arguments, start, stop),
                                            **fingerprint})
            if progress_bar is not None:
                progress_bar.update(stop - start)


def _close(client, cluster) -> None:
    if client is not None:
        client.close()
    if cluster is not None:
        cluster.close()


def _chunk_ok(campaign: Campaign, path: Path, runs: int) -> bool:
    """A finished chunk file of this campaign that loads and holds every
    column; a damaged one (an interrupted disk, a truncated copy) is removed,
    to be computed again. A whole chunk of another campaign (another
    fingerprint, or other seeds) is refused: it is somebody's result."""
    if not path.exists():
        return False
    found, seeds = None, None
    try:
        with np.load(path) as data:
            keys = [f"{name}/{column}" for name in campaign.estimators for column in CHUNK_COLUMNS]
            ok = all(key in data.files and data[key].shape == (runs,) for key in keys + ["seed"])
            found = str(data["fingerprint"]) if "fingerprint" in data.files else None
            seeds = data["seed"] if ok else None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        ok = False
    mine = found == campaign.fingerprint()
    if not ok and (mine or found is None):    # damaged on its way to or on the disk
        path.unlink()
        return False
    start = int(path.stem.split("-")[1])
    expected = seed_range(campaign.base_seed + start, runs)
    if not mine or not np.array_equal(seeds, expected):
        what = ("other seeds" if mine else "other settings" if found else "no fingerprint")
        raise InvalidParameterError(
            "resume", str(path.parent.parent), f"chunk {CHUNKS}/{path.name} belongs to another "
            f"campaign ({what}); remove it to compute it again, or choose another --out")
    return True


def load_campaign(campaign: Campaign, out) -> pd.DataFrame:
    """The finished chunks joined in run order: one row per (run, estimator)."""
    parts, usages = [], {name: [] for name in campaign.estimators}
    for start, stop in campaign.chunks():
        with np.load(chunk_path(out, start, stop)) as data:
            for name in campaign.estimators:
                part = pd.DataFrame({"run": np.arange(start, stop), "seed": data["seed"],
                                     "estimator": name})
                for column in CHUNK_COLUMNS:
                    part[column] = data[f"{name}/{column}"]
                parts.append(part)
                if f"{name}/usage" in data.files:      # chunks of older campaigns have none
                    usages[name].append(Usage(**json.loads(str(data[f"{name}/usage"]))))
    frame = pd.concat(parts, ignore_index=True)
    order = {name: i for i, name in enumerate(campaign.estimators)}
    frame["_order"] = frame["estimator"].map(order)
    frame = (frame.sort_values(["_order", "run"], kind="stable").drop(columns="_order")
             .reset_index(drop=True))
    #: estimator → what its runs made of their readings (benchmarks.sensor_use.Usage)
    frame.attrs["usage"] = {name: Usage.combined(found) for name, found in usages.items()
                            if found}
    return frame
