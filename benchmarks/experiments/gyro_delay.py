"""The gyro's delay on a recording, found without its reference: the delay
under which an estimator's innovations are likeliest (the tuner's
``likelihood`` objective, :mod:`benchmarks.experiments.objectives`), by the
bounded Brent method of :func:`benchmarks.experiments.tuning.minimize_bounded`
over the replayed recording (:mod:`benchmarks.experiments.replay`).
``replay --gyro-delay auto`` runs it.
"""
from __future__ import annotations

from benchmarks.experiments.objectives import Objective, recording_case
from benchmarks.experiments.replay import (DEFAULT_INTERVAL_S, DEFAULT_NOISE_DEG, load_replay,
                                           open_dataset)
from benchmarks.experiments.tuning import minimize_bounded
from benchmarks.output import progress


#: The gyro delays :func:`likeliest_gyro_delay` searches, in samples (an
#: IMU's filters delay its rate; a few samples early is searched too).
DELAY_SEARCH_SAMPLES = (-4.0, 8.0)


def likeliest_gyro_delay(dataset: str, estimator: str = "mekf",
                         interval_s: float = DEFAULT_INTERVAL_S,
                         noise_deg: float = DEFAULT_NOISE_DEG, seed: int = 0,
                         settings=None, allow_imports=(), quiet: bool = True):
    """The gyro delay (seconds) under which ``estimator``'s innovations are
    likeliest on ``dataset`` — the tuner's ``likelihood`` objective, which
    reads no reference attitude — by the bounded Brent method over
    :data:`DELAY_SEARCH_SAMPLES`; with the minimisation's log, and whether
    the delay found is at an end of the search (the likeliest may lie beyond)."""
    dt = open_dataset(dataset)[0].dt

    def loss(samples: float) -> float:
        data = load_replay(dataset, interval_s, noise_deg, seed, settings, allow_imports,
                           gyro_delay_s=samples * dt, scored=False)   # no reference read
        return Objective(estimator, "likelihood", [recording_case(data, dataset)])({})

    with progress(desc="gyro delay", unit="eval", quiet=quiet) as bar:
        def counted(samples):
            bar.update()
            return loss(samples)
        log = minimize_bounded(counted, DELAY_SEARCH_SAMPLES, xtol=0.02)
    at_bound = min(abs(log.x - end) for end in DELAY_SEARCH_SAMPLES) <= 0.05
    return log.x * dt, log, at_bound
