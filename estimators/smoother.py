r"""An offline MEKF: the forward filter and the same filter run backward in
time, fused at every sample (the two-filter smoother).

A smoother estimates each attitude from the whole record, the readings
after it as well as before: offline, for a recording that is over. Fraser &
Potter's two-filter form (Fraser & Potter, "The optimum linear smoother as
a combination of two optimum linear filters", IEEE TAC 14(4), 1969; Simon,
*Optimal State Estimation*, 2006, §9.4, fixed-interval smoothing) runs the
filter forward, :math:`\hat q_f, P_f`, and backward from
the end, :math:`\hat q_b, P_b` (its prediction at each sample, before
that sample's readings, which the forward estimate holds), and combines
the two independent estimates at each sample by their information, over the whole error state (the
attitude's body-frame error and the bias, as the MEKF keeps them; Markley &
Crassidis 2014, §6.2):

.. math::

    \delta = \begin{bmatrix} \log(\hat q_f^{-1} \otimes \hat q_b) \\
    \hat\beta_b - \hat\beta_f \end{bmatrix}, \qquad
    G = P_f (P_f + P_b)^{-1}, \qquad
    \hat q_s = \hat q_f \otimes \exp\bigl((G\delta)_{1:3}\bigr), \quad
    \hat\beta_s = \hat\beta_f + (G\delta)_{4:6}, \quad P_s = P_f - G P_f.

With the MEKF's hard-iron states (``magnetometer_bias_states``), :math:`\delta`
and :math:`G\delta` carry the hard iron's difference too, which time reversal
leaves as it is; each pass starts its hard iron from zero with its prior.

Fusing the attitudes' marginals alone would not be the smoother: the bias
carries what the two passes know of each other's attitude (on a linear case,
the attitude-only fusion is off the RTS smoother by a tenth of the error;
the full state's equals it, ``tests/test_imu_models.py``). The backward filter is the forward one's class and settings on the
time-reversed record: the rates negated and each reading moved to the
interval it covers in reverse (:func:`reversed_rates`), the readings
reversed; it starts from the forward filter's last attitude and bias (the
bias of the reversed gyro is the negated bias) with the filter's prior
covariance, so it converges from its first sample. (The fusion takes the two
as independent; their shared start makes :math:`P_s` a little optimistic
near the record's end.) The forward pass outputs its posterior, the
backward its prior, whatever ``output`` the settings give.

**The field's timing** (``fit_magnetometer_delay``, on by default). A
MEMS magnetometer filtered inside its sensor reads late against its gyro
(BROAD's 12–14 ms; a phone's tens of milliseconds). Each pass then reads a
field late in its own direction of time, and the two disagree by degrees in
every fast turn. An offline filter has the whole record to time it: on a
recording (:func:`benchmarks.engine.recorded.run_recorded`, which reads
this setting, as for offline VQF's), the field's delay is fitted from how
it turns against the gyro before the passes (no reference read) and, where
the fit is clear, each reading is taken at its sample's time — what
``--magnetometer-delay auto`` does for every estimator (:mod:`sensors.delay`);
with the heading model only (a recording's IMU). Where the recording's
field was timed already (``--magnetometer-delay``, given or fitted), its
inputs turn the setting off (:mod:`benchmarks.broad.inputs`): none is taken
out twice. :meth:`track` itself takes the readings as given.

VQF's offline mode (Laidig & Seel 2023, §3.5, ``offlineVQF``) is the peer:
forward and backward passes of its bias estimator, fused in information
form, and zero-phase filtering; :class:`estimators.peers.OfflineVQF` runs it.
"""
from __future__ import annotations

import copy
import inspect
from dataclasses import replace

import numpy as np

from dynamics.validation import boolean
from estimators.base import (EstimateTrace, checked_vector_record, quiet_overflow,
                             observations_at)
from estimators.mekf import MultiplicativeEKF
from estimators.readings import checked_rates


def reversed_rates(omega: np.ndarray, interpolation: str) -> np.ndarray:
    """The gyro's readings of the time-reversed record, negated, each where
    the filter's ``rate_interpolation`` takes it: ``"trapezoid"`` takes the
    two ends of a step, symmetric in time; ``"end"`` takes step ``k``'s
    reading for the interval before it, which reversed is the interval after
    it; ``"hold"`` takes it for the interval after it, reversed the one before."""
    reverse = -omega[::-1]
    if interpolation == "trapezoid" or len(omega) < 2:
        return np.ascontiguousarray(reverse)
    shifted = np.empty_like(omega)
    if interpolation == "end":              # reversed step m covers original N-m ... N-1-m
        shifted[1:], shifted[0] = reverse[:-1], reverse[0]
    else:                                   # "hold": reversed step m is taken from N-2-m
        shifted[:-1], shifted[-1] = reverse[1:], reverse[-1]
    return shifted


def reversed_readings(vectors) -> tuple:
    """Each :class:`~sensors.vector.VectorReadings` of ``vectors`` reversed in time."""
    return tuple(replace(v, **{name: np.ascontiguousarray(getattr(v, name)[::-1])
                               for name in ("body", "reference", "available", "variance")})
                 for v in vectors)


#: Samples fused at a time: the fusion's temporaries (a dozen arrays of
#: covariances) stay some ten MB however long the recording.
FUSE_CHUNK = 1 << 13


def fuse(forward, backward) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two-filter fusion (module docstring) of the forward pass's
    ``(q, β, P)`` — ``(N, 4)`` attitudes, ``(N, 3)`` biases, ``(N, 6, 6)``
    covariances of the body-frame error state — with the backward pass's,
    whose bias is the reversed gyro's (negated here). Returns the fused
    attitudes, biases and covariances; where one pass is not finite, the
    other's. Fused :data:`FUSE_CHUNK` samples at a time, each sample alone:
    the same numbers as all at once."""
    q_f, b_f, P_f = (np.asarray(x, dtype=float) for x in forward)
    q_b, b_b, P_b = (np.asarray(x, dtype=float) for x in backward)
    flip = _flip(P_f.shape[-1])
    fused = (q_f.copy(), b_f.copy(), P_f.copy())
    for start in range(0, len(q_f), FUSE_CHUNK):
        part = slice(start, start + FUSE_CHUNK)
        # the reversed gyro's bias is −β
        _fuse_part(tuple(x[part] for x in fused),
                   (q_b[part], b_b[part] * flip[3:], P_b[part] * np.outer(flip, flip)))
    return fused


def _fuse_part(fused, backward) -> None:
    """:func:`fuse` on part of the samples: ``fused`` (views into the
    output, holding the forward pass) fused in place with ``backward``."""
    q_b, b_b, P_b = backward
    ok_f, ok_b = _finite(*fused), _finite(q_b, b_b, P_b)
    for mine, theirs in zip(fused, backward):
        mine[~ok_f] = theirs[~ok_f]
    both = ok_f & ok_b
    if not both.any():
        return
    from scipy.spatial.transform import Rotation  # here: a scenario is built without scipy
    q_f, b_f, Pf = (x[both] for x in fused)
    forward_rotation = Rotation.from_quat(q_f[:, [1, 2, 3, 0]])
    delta = np.concatenate(
        [(forward_rotation.inv() * Rotation.from_quat(q_b[both][:, [1, 2, 3, 0]])).as_rotvec(),
         b_b[both] - b_f], axis=1)
    gain = np.linalg.solve(Pf + P_b[both], Pf).transpose(0, 2, 1)   # P_f (P_f + P_b)⁻¹
    step = np.einsum("nij,nj->ni", gain, delta)
    quat = (forward_rotation * Rotation.from_rotvec(step[:, :3])).as_quat()[:, [3, 0, 1, 2]]
    fused[0][both] = quat * np.sign(np.sum(quat * q_f, axis=1))[:, None]
    fused[1][both] = b_f + step[:, 3:]
    fused[2][both] = Pf - gain @ Pf


def _flip(size: int) -> np.ndarray:
    """The sign of each error state under time reversal: the gyro bias's
    turns, the attitude's and a hard iron's (states 7–9) do not."""
    signs = np.ones(size)
    signs[3:6] = -1.0
    return signs


def _finite(q, b, P) -> np.ndarray:
    return np.isfinite(q).all(axis=1) & np.isfinite(b).all(axis=1) & \
        np.isfinite(P).all(axis=(1, 2))


def diverged_step(forward: int | None, backward: int | None, n: int) -> int | None:
    """Where a smoothed record of ``n`` steps diverged: where both passes had
    (fusion takes the finite one), from the later of the forward pass's step
    and the backward pass's, counted from the record's end (None: never)."""
    if forward is None or backward is None:
        return None
    return max(forward, n - 1 - backward)


def filter_pass(mekf: MultiplicativeEKF, omega, star, available, vectors=None) -> tuple:
    """``mekf`` (reset) over a whole record: each step's output ``(q, β, P)``
    as ``(N, 4)``, ``(N, 3)`` and ``(N, 6, 6)`` arrays (with hard-iron
    states, ``β`` is followed by the hard iron, ``(N, 6)``, and ``P`` is 9x9)."""
    omega, star, available, _ = mekf._start_record(omega, star, available)
    records = checked_vector_record(vectors, len(omega))
    n, size = len(omega), mekf.state_size
    quat, bias, covariance = np.empty((n, 4)), np.empty((n, size - 3)), np.empty((n, size, size))
    with quiet_overflow():
        for k in range(n):
            quat[k] = mekf.step(omega[k], star[k] if available[k] else None, 0.0,
                                observations_at(records, k))
            bias[k, :3], covariance[k] = mekf._output[1], mekf._output[2]
            if mekf.magnetometer_bias_states:
                bias[k, 3:] = mekf.magnetometer_bias
    return quat, bias, covariance


def _with_mekf_settings(init):
    """``init`` (keyword-only settings of its own, then ``**settings``)
    declared with the MEKF's settings and its own: the settings' tools read
    a constructor's signature, and each setting stays declared once."""
    own = [p for p in inspect.signature(init).parameters.values()
           if p.kind is inspect.Parameter.KEYWORD_ONLY]
    signature = inspect.signature(MultiplicativeEKF.__init__)
    init.__signature__ = signature.replace(parameters=[*signature.parameters.values(), *own])
    return init


class MekfSmoother(MultiplicativeEKF):
    """The MEKF forward and backward over a whole record, fused (module
    docstring): offline. Its settings are the MEKF's and
    ``fit_magnetometer_delay`` (module docstring): ``[estimators.mekf]``
    applies to it, and ``[estimators.mekf-smoother]`` over that. It runs on
    whole records only (:meth:`run`, :meth:`track`; on a recording the engine
    runs both passes through the MEKF's kernel,
    :mod:`benchmarks.engine.recorded`), never step by step."""

    name = "mekf-smoother"
    label = "MEKF smoother"
    #: It reads the whole record before its first estimate.
    mode = "offline"

    @classmethod
    def scenario_section(cls, scenario) -> dict:
        section = MultiplicativeEKF.scenario_section(scenario)
        section.update(super().scenario_section(scenario))
        return section

    @_with_mekf_settings
    def __init__(self, *, fit_magnetometer_delay: bool = True, **settings):
        self.fit_magnetometer_delay = boolean("fit_magnetometer_delay", fit_magnetometer_delay)
        super().__init__(**settings)

    def step(self, *args, **kwargs):
        raise TypeError(f"{self.name} is offline: it estimates from the whole record "
                        "(run or track), not step by step")

    def pass_filter(self, backward_from=None) -> MultiplicativeEKF:
        """The MEKF with these settings, reset: the forward pass's, or with
        ``backward_from`` (the forward pass's last filter) the backward
        pass's, started from its last attitude and negated bias."""
        mekf = MultiplicativeEKF.__new__(MultiplicativeEKF)
        mekf.__dict__.update(copy.deepcopy(self.__dict__))
        mekf.output = "posterior"
        if backward_from is not None:
            mekf.initial_attitude = backward_from.q_hat.copy()
            mekf.initial_bias_radps = -backward_from.beta_hat.copy()
            mekf.output = "prior"
        mekf.reset()
        return mekf

    def _keep(self, forward: MultiplicativeEKF, backward: MultiplicativeEKF, n: int) -> None:
        """The forward pass's state and counts as this smoother's, and where
        it diverged (:func:`diverged_step`)."""
        self.__dict__.update(forward.__dict__)
        self.diverged_step = diverged_step(forward.diverged_step, backward.diverged_step, n)

    def track(self, omega_meas_radps, star_tracker_quat, available, offset_s=None, *,
              vectors=None, progress=None) -> EstimateTrace:
        """The forward and backward passes on the per-run path (the
        reference), fused; the rejections are the forward pass's."""
        if offset_s is not None and np.any(np.asarray(offset_s) != 0.0):
            raise ValueError("offset_s: the smoother takes readings on the gyro's grid only "
                             "(no reading between two steps)")
        omega = checked_rates(omega_meas_radps)
        forward_filter = self.pass_filter()
        forward = filter_pass(forward_filter, omega, star_tracker_quat, available, vectors)
        backward_filter = self.pass_filter(backward_from=forward_filter)
        backward = filter_pass(
            backward_filter, reversed_rates(omega, self.rate_interpolation),
            np.ascontiguousarray(np.asarray(star_tracker_quat)[::-1]),
            np.ascontiguousarray(np.asarray(available)[::-1]),
            None if vectors is None else reversed_readings(vectors))
        quat, bias, covariance = fuse(forward, tuple(x[::-1] for x in backward))
        self._keep(forward_filter, backward_filter, len(omega))
        if progress is not None:
            progress.update(len(omega))
        rejected = {}
        for k, sensor in forward_filter.rejections:
            rejected.setdefault(sensor, []).append(k)
        return EstimateTrace(quat=quat, attitude_covariance=covariance[:, :3, :3],
                             bias_radps=bias[:, :3], bias_covariance=covariance[:, 3:6, 3:6],
                             rejected={sensor: np.array(steps)
                                       for sensor, steps in rejected.items()})

    def run(self, omega_meas_radps, star_tracker_quat, available, offset_s=None, *,
            vectors=None, progress=None) -> np.ndarray:
        return self.track(omega_meas_radps, star_tracker_quat, available, offset_s,
                          vectors=vectors, progress=progress).quat
