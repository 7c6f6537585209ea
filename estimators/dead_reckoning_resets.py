r"""Dead reckoning with star-tracker resets.

.. math::

    \hat q_k = \begin{cases}
        z_k & \text{if a star tracker reading is available at } k,\\
        f(\hat q_{k-1}, \tilde\omega_k) & \text{otherwise,}
    \end{cases}

with ``f`` the normalised first-order step of :mod:`estimators.model`
(the workshop model, "The three estimators", item 2). The error is that of
the star tracker at each reading plus the gyro's angle random walk since the
last one.
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import IDENTITY
from dynamics.validation import boolean
from estimators import sensing
from estimators.dead_reckoning import DeadReckoning
from estimators.model import propagate
from estimators.settings import DEFAULT_DT_S


class DeadReckoningWithResets(DeadReckoning):
    """Gyro propagation, replaced by each star tracker reading when it arrives.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,) array-like
        Starting estimate ``q̂[-1]``, scalar-first; normalised.
    rate_timing : {"workshop", "step-average", "end"}
        As for :class:`~estimators.DeadReckoning`.
    align_sign : bool
        Flip a reading to the sign nearest the current estimate (default).
    on_invalid : {"raise", "skip"}
        As for :class:`~estimators.DeadReckoning`.
    """

    name = "dead-reckoning-resets"
    label = "Dead Reckoning w/ Star Tracker Resets"
    reads = frozenset({sensing.STAR_TRACKER})
    needs = (frozenset({sensing.STAR_TRACKER}),)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 rate_timing: str = "workshop", align_sign: bool = True,
                 on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, rate_timing=rate_timing,
                         on_invalid=on_invalid)
        self.align_sign = boolean("align_sign", align_sign)

    def _step(self, omega_meas_radps, star_tracker_quat=None) -> np.ndarray:
        self._advance(omega_meas_radps)
        if star_tracker_quat is not None:
            self.attitude = self._aligned(star_tracker_quat)
        return self.attitude.copy()

    def _aligned(self, star_tracker_quat) -> np.ndarray:
        """The reading, as the representative nearest the estimate if asked
        (q and -q are one attitude: the held state never jumps across the sphere)."""
        reading = np.array(star_tracker_quat, dtype=float)
        if self.align_sign and reading @ self.attitude < 0:
            reading = -reading
        return reading

    applies_reading_times = True

    def _step_at(self, omega_meas_radps, star_tracker_quat, offset_s: float) -> np.ndarray:
        """A reading taken ``τ`` after ``t_k``: output the estimate of ``t_k``,
        take the reading as the attitude at ``t_k + τ``, and leave the next
        propagation the rest of the step, ``Δt − τ`` (with step-average timing
        it is made now, with this step's rate)."""
        self._advance(omega_meas_radps)
        estimate = self.attitude.copy()
        self.attitude = self._aligned(star_tracker_quat)
        if self.rate_timing != "step-average":
            self._next_dt = self.dt - offset_s
        else:
            self.attitude = propagate(self.attitude, self._pending_rate, self.dt - offset_s)
            self._pending_rate = None
        return estimate
