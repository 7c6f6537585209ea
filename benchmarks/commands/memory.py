"""The memory checks the commands run before any work: what cannot fit is
refused with the numbers, never started (:mod:`benchmarks.resources`)."""
from __future__ import annotations


def engine_memory(args, scenario) -> None:
    """A command on the streaming engine alone: its memory is flat."""
    from benchmarks.resources import check_memory, engine_bytes
    check_memory(scenario, engine_bytes(scenario.n_steps))


def per_run_memory(traced: bool):
    """The per-run path's records of each estimator (three if none are named)."""
    def check(args, scenario) -> None:
        from benchmarks.resources import check_memory, engine_bytes, per_run_bytes
        estimators = len(getattr(args, "estimators", ()) or ()) or 3
        check_memory(scenario, per_run_bytes(scenario.n_steps, estimators, traced),
                     streaming_bytes=engine_bytes(scenario.n_steps))
    return check
