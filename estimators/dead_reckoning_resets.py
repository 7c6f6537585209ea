r"""Dead reckoning with star-tracker resets.

.. math::

    \hat q_k = \begin{cases}
        z_k & \text{if a star tracker reading is available at } k,\\
        f(\hat q_{k-1}, \tilde\omega_k) & \text{otherwise,}
    \end{cases}

with ``f`` the normalised first-order step of :mod:`estimators.model`
(workshop model, SPEC "The three estimators", item 2). The error is that of
the star tracker at each reading plus the gyro's angle random walk since the
last one.
"""
from __future__ import annotations

import numpy as np

from estimators.dead_reckoning import DeadReckoning


class DeadReckoningWithResets(DeadReckoning):
    """Gyro propagation, replaced by each star tracker reading when it arrives.

    Parameters
    ----------
    dt : float
        Gyro step, seconds.
    initial_attitude : (4,) array-like
        Starting estimate ``q̂[-1]``, scalar-first; normalised.
    rate_timing : {"workshop", "step-average"}
        As for :class:`~estimators.DeadReckoning`.
    """

    name = "dead-reckoning-resets"
    label = "Dead Reckoning w/ Star Tracker Resets"

    def step(self, omega_meas_radps, star_tracker_quat=None) -> np.ndarray:
        self._advance(omega_meas_radps)
        if star_tracker_quat is not None:
            self.attitude = np.array(star_tracker_quat, dtype=float)
        return self.attitude.copy()
