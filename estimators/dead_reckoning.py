r"""Dead reckoning: integrate the gyro, ignore the star tracker.

.. math:: \hat q_k = f(\hat q_{k-1}, \tilde\omega_k), \qquad \hat q_{-1} = q_0,

with ``f`` the normalised first-order step of :mod:`estimators.model`
(the workshop model, "The three estimators", item 1). Gyro white noise of
power ``p`` makes the error grow as an angle random walk: after ``t``
seconds each axis has drifted by about ``√(p t)`` radians (Markley &
Crassidis 2014, §6.2.2).

Which step a reading belongs to: the workshop's order (the default,
``rate_timing="workshop"``) uses :math:`\tilde\omega_k` to reach step ``k``.
The flight gyro model of :mod:`sensors.gyro` reports :math:`\tilde\omega_k`
as the average rate from :math:`t_k` to :math:`t_{k+1}`, as the filters use it;
``rate_timing="step-average"`` matches that,
:math:`\hat q_k = f(\hat q_{k-1}, \tilde\omega_{k-1})` with
:math:`\hat q_0 = q_0`, and so avoids a constant lag of one step's rotation
(23 arcsec at 0.0011 rad/s and 10 Hz). An IMU's reading is the mean rate
over the interval *before* its sample (its rate filtered inside the
sensor): ``rate_timing="end"``,
:math:`\hat q_k = f(\hat q_{k-1}, \tilde\omega_k)` with :math:`\hat q_0 =
q_0` (reading 0 covers the time before the start), as the MEKF's
``rate_interpolation = "end"`` takes it; a recording's scenario sets it
(:data:`benchmarks.experiments.replay.RECORDED_GYRO`).
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import IDENTITY
from dynamics.validation import one_of
from estimators.base import AttitudeEstimator
from estimators.model import propagate
from estimators.settings import DEFAULT_DT_S

RATE_TIMINGS = ("workshop", "step-average", "end")


class DeadReckoning(AttitudeEstimator):
    """Gyro-only attitude propagation.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,) array-like
        Starting estimate (``q̂[-1]``, or ``q̂[0]`` with step-average or end timing),
        scalar-first; normalised.
    rate_timing : {"workshop", "step-average", "end"}
        Whether ``ω̃[k]`` takes the estimate to step ``k`` (the workshop; with
        ``"end"`` from step ``k - 1``, reading 0 unused) or from ``k`` to
        ``k + 1`` (see the module docstring).
    on_invalid : {"raise", "skip"}
        What to do with an unusable measurement (see
        :meth:`~estimators.AttitudeEstimator.step`).
    """

    #: Dead reckoning integrates the gyro alone (with resets: and the star tracker).
    uses_vector_readings = False
    reads = frozenset()
    name = "dead-reckoning"
    label = "Dead Reckoning"

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 rate_timing: str = "workshop", on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        self.rate_timing = one_of("rate_timing", rate_timing, RATE_TIMINGS)
        self.reset()

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """The scenario's settings, and the rate timing: the workshop's on its
        sensors (the exercise's numbers), ``"step-average"`` on any other, so
        that the estimate at ``t = 0`` is the initial attitude itself."""
        settings = super().settings_from_scenario(scenario)
        settings["rate_timing"] = ("workshop" if getattr(scenario, "is_workshop_sensors", True)
                                   else "step-average")
        return settings

    #: It ignores readings, wherever they fall.
    applies_reading_times = True

    def reset(self) -> None:
        self.attitude = self.initial_attitude.copy()
        self._pending_rate = None
        #: Whether a reading was taken since the reset ("end": reading 0 is not integrated).
        self._started = False
        #: The time the next propagation covers: dt, or what is left of a step
        #: after a reading taken within it (dead reckoning with resets).
        self._next_dt = self.dt

    def _advance(self, omega_meas_radps) -> None:
        """Propagate with the rate that belongs to this step under ``rate_timing``."""
        omega = np.asarray(omega_meas_radps, float)
        step, self._next_dt = self._next_dt, self.dt
        started, self._started = self._started, True
        if self.rate_timing == "end" and not started:     # reading 0: the time before the start
            return
        if self.rate_timing != "step-average":
            self.attitude = propagate(self.attitude, omega, step)
            return
        if self._pending_rate is not None:
            self.attitude = propagate(self.attitude, self._pending_rate, step)
        self._pending_rate = omega

    def _step(self, omega_meas_radps, star_tracker_quat=None) -> np.ndarray:
        self._advance(omega_meas_radps)
        return self.attitude.copy()
