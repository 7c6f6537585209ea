"""What a run will hold in memory, estimated before any work starts.

The per-run path keeps, for every step, the truth (and the integrator's copy
of it), the sensor readings and each estimator's output; with traces also its
covariances and bias. The batched engine streams the truth, the noise and its
statistics in blocks, so what it holds does not grow with the run's length
(runs up to ``TRUTH_CACHE_STEPS`` keep their truth whole, which caps it). A
run that cannot fit is refused with one line naming the parameter and the
limit, and the streaming path is suggested where it would fit.
"""
from __future__ import annotations

import os

from dynamics.validation import InvalidParameterError

#: Bytes a per-run simulation keeps per step: truth with the integrator's own
#: copy (~150), sensor readings with the true bias (~90); per estimator its
#: estimate and error (~40), with traces its 3x3 covariances, bias and NIS (~200).
PER_RUN_BYTES_PER_STEP = 240
ESTIMATOR_BYTES_PER_STEP = 40
TRACED_ESTIMATOR_BYTES_PER_STEP = 240
#: Runs of up to this many steps take their truth whole from a cache (64 bytes
#: per step: 32 MB here, see benchmarks.simulation.truth_blocks); longer ones
#: integrate it block by block, so their memory stays flat.
TRUTH_CACHE_STEPS = 500_000
#: Making the truth whole costs ~150 bytes per step (the integrator's samples
#: and their copy); the engine does so only up to TRUTH_CACHE_STEPS steps.
TRUTH_BYTES_PER_STEP = 150
#: The engine's buffers for a chunk of 1024 runs: the noise of a block
#: (61 MB), the median histograms (15 MB per estimator) and the state; they
#: grow with the chunk's runs.
ENGINE_CHUNK_BYTES = 160 * 2**20
ENGINE_CHUNK_RUNS = 1024
#: Use at most this share of the machine's memory.
MEMORY_SHARE = 0.8


def machine_memory_bytes() -> int:
    """Physical memory of this machine."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def per_run_bytes(n_steps: int, estimators: int, traced: bool = False) -> int:
    each = TRACED_ESTIMATOR_BYTES_PER_STEP if traced else ESTIMATOR_BYTES_PER_STEP
    return n_steps * (PER_RUN_BYTES_PER_STEP + estimators * each)


def engine_bytes(n_steps: int, chunk_runs: int = ENGINE_CHUNK_RUNS) -> int:
    """What the engine holds for chunks of ``chunk_runs`` runs of ``n_steps``:
    flat in the run's length above the truth cache."""
    return (min(n_steps, TRUTH_CACHE_STEPS) * TRUTH_BYTES_PER_STEP
            + ENGINE_CHUNK_BYTES * max(chunk_runs, ENGINE_CHUNK_RUNS) // ENGINE_CHUNK_RUNS)


def check_memory(scenario, needed_bytes: int, *, streaming_bytes: int | None = None,
                 limit_bytes: int | None = None, chunk_runs: int | None = None) -> None:
    """Refuse a run that needs more than the machine can give.

    ``streaming_bytes`` is what the engine would need for the same scenario;
    the message suggests ``montecarlo`` when that fits.
    """
    limit = int(MEMORY_SHARE * machine_memory_bytes()) if limit_bytes is None else limit_bytes
    if needed_bytes <= limit:
        return
    if chunk_runs is not None and chunk_runs > ENGINE_CHUNK_RUNS:
        most = ENGINE_CHUNK_RUNS * (limit // ENGINE_CHUNK_BYTES)
        raise InvalidParameterError(
            "chunk_size", chunk_runs, f"a chunk of {chunk_runs:,} runs needs about "
            f"{needed_bytes / 2**30:,.1f} GiB and this machine allows {limit / 2**30:.1f} GiB:"
            f" at most about {most:,} runs per chunk here")
    per_step = needed_bytes / scenario.n_steps
    longest = limit / per_step * scenario.dt
    hint = ""
    if streaming_bytes is not None and streaming_bytes <= limit:
        hint = ("; the streaming engine (attitude-bench montecarlo) needs about "
                f"{streaming_bytes / 2**30:.1f} GiB for it")
    raise InvalidParameterError(
        "tstop", scenario.tstop,
        f"needs about {needed_bytes / 2**30:,.1f} GiB ({scenario.n_steps:,} steps) and this "
        f"machine allows {limit / 2**30:.1f} GiB: at most about tstop = {longest:,.0f} s here"
        f"{hint}")
