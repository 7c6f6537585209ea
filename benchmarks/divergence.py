"""Runs that diverged: counted, never scored as numbers.

An estimator *diverges* when its estimate or its covariance stops being
finite (:meth:`estimators.AttitudeEstimator.state_is_finite`, and the same
test in the engine's kernels). From that step on its estimates and errors
are NaN, so the run's statistics are NaN — never the 0° that ``min(1, NaN)``
would give — and the means over runs leave it out. Every command counts the
diverged runs, says so on stderr, and exits with :data:`EXIT_DIVERGED`
unless it was given ``--allow-divergence``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Exit status of a command whose results include a diverged run.
EXIT_DIVERGED = 3


@dataclass
class DivergenceReport:
    """Per estimator: runs counted, runs diverged and the earliest step."""

    dt: float
    runs: dict = field(default_factory=dict)
    diverged: dict = field(default_factory=dict)
    first_step: dict = field(default_factory=dict)

    def add(self, name: str, steps) -> None:
        """Count runs of ``name`` with diverged steps ``steps`` (-1: did not diverge)."""
        steps = np.atleast_1d(np.asarray(steps, dtype=np.int64))
        lost = steps[steps >= 0]
        self.runs[name] = self.runs.get(name, 0) + len(steps)
        self.diverged[name] = self.diverged.get(name, 0) + len(lost)
        if len(lost):
            earliest = int(lost.min())
            self.first_step[name] = min(earliest, self.first_step.get(name, earliest))

    @property
    def total(self) -> int:
        """Diverged runs over all estimators."""
        return sum(self.diverged.values())

    def lines(self) -> list[str]:
        """One line per estimator that diverged."""
        return [f"{name} diverged in {count} of {self.runs[name]} runs (first at step "
                f"{self.first_step[name]}, t = {self.first_step[name] * self.dt:g} s): its "
                "estimate or covariance stopped being finite; those runs' statistics are NaN "
                "and left out of the means"
                for name, count in self.diverged.items() if count]


def report_of(dt: float, steps_by_name: dict) -> DivergenceReport:
    """A report from ``{name: diverged steps}``."""
    report = DivergenceReport(dt)
    for name, steps in steps_by_name.items():
        report.add(name, steps)
    return report
