"""Recorded readings through the engine: one estimator over one recording
(a gyro and vector readings, as :mod:`benchmarks.broad` makes them from a
real IMU), by the fastest path that gives the per-run class's numbers.

* An estimator with a Monte Carlo kernel (:data:`~benchmarks.engine.kernels.
  KERNELS`) that models what it needs runs through that kernel, one run over
  one block that holds the whole recording: the recorded rates are the
  block's "true" rates with a noise-free gyro (σ = 0, no bias, no scale:
  the kernel's reading is then the recorded rate exactly), the tracker is out
  throughout, and the vector readings are the recording's. The kernel's
  error against the block's truth is not used (the truth is the identity):
  the estimates are kept and scored by the caller.
* The MEKF's smoother (:mod:`estimators.smoother`) runs its forward and
  backward passes through the MEKF's kernel, keeping each output's
  attitude covariance, and fuses them as the per-run class does.
* Madgwick's and Mahony's filters run through their compiled step functions
  (:mod:`benchmarks.engine.kernels.complementary`).
* An estimator with a ``run_batch(omega, vectors)`` method (the peers'
  adapters, :mod:`estimators.peers`, which feed their library the whole
  recording at once; TRIAD, :mod:`estimators.static`, whose every sample is
  its own solution) runs so, unless that method answers None for this
  recording (missing readings, say).
* Anything else runs on the per-run path (``estimator.run``).

An offline estimator that asks for it (``fit_magnetometer_delay``: the
smoother's and offline VQF's setting, on by default) reads the field taken
at its samples' times wherever its delay against the gyro is clear
(:func:`field_timed`): having the whole recording, it can time it.

Every path reads its settings and its start off the per-run object after
its reset; the tests hold each to the per-run path to 1e-9 at every sample.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from benchmarks.engine.kernels import KERNELS, kernel, settings_limitation
from dynamics.quaternion import IDENTITY, quat_multiply
from estimators.complementary import NWU_TO_ENU, declination_turn
from estimators.mekf import estimates_hard_iron
from estimators.readings import checked_rates, checked_vector_record
from estimators.records import RecordRuns
from estimators.smoother import (MekfSmoother, diverged_step, fuse, reversed_readings,
                                 reversed_rates)


@dataclass(frozen=True)
class RecordedRun:
    """An estimator's estimates over a recording, ``(N, 4)`` body → reference."""

    estimates: np.ndarray
    #: The first sample whose estimate was not finite (None: never).
    diverged_step: int | None
    #: sensor → the readings gating rejected.
    rejected: dict = field(default_factory=dict)
    #: "kernel", "compiled", "batch" or "per-run": the path it took.
    path: str = "per-run"
    #: With ``innovations``: the sum of ln det S + NIS over the applied
    #: updates and their count (None for an estimator without innovations).
    likelihood: tuple | None = None
    #: ``(N, 3, 3)``: each output's attitude covariance (rad², body-frame
    #: error), where the filter keeps one (a kernel that reports one, the
    #: smoother's fusion, a per-run class's ``track``); None elsewhere.
    attitude_covariance: np.ndarray | None = None
    #: The magnetometer's delay against the gyro (s) taken out of its
    #: readings first (:func:`field_timed`); None where none was.
    magnetometer_delay_s: float | None = None


def field_timed(estimator, omega: np.ndarray, vectors: tuple) -> tuple:
    """``vectors`` as ``estimator`` reads them, and the delay fit applied
    (None where none was): where its ``fit_magnetometer_delay`` asks and it
    reads the field as a heading or alone (a recording's IMU), the
    magnetometer's readings taken at their samples' times if their delay
    against the gyro ``omega`` is clear — what ``--magnetometer-delay auto``
    does (:func:`sensors.delay.timed_readings`)."""
    if not (getattr(estimator, "fit_magnetometer_delay", False)
            and getattr(estimator, "magnetometer_model", "heading") == "heading"):
        return vectors, None
    from sensors.delay import timed_readings      # here: few runs time their field
    timed, applied = [], None
    for readings in vectors:
        if readings.sensor == "magnetometer":
            fit, body = timed_readings(omega, readings.body, readings.available, estimator.dt)
            if body is not None:
                applied, readings = fit, replace(readings, body=body)
        timed.append(readings)
    return tuple(timed), applied


def path_of(estimator, vectors=()) -> str:
    """The path ``estimator`` (a per-run object) takes on a recording with
    ``vectors`` (module docstring)."""
    from benchmarks.engine.kernels import complementary
    name = getattr(estimator, "name", None)
    if isinstance(estimator, MekfSmoother):      # its kernel passes keep six states
        return "per-run" if estimates_hard_iron(vars(estimator)) else "kernel"
    if name in KERNELS and type(estimator).__module__.startswith("estimators.") and \
            settings_limitation(kernel(name), name, vars(estimator)) is None:
        module = kernel(name)
        needs_vectors = bool(vectors) and estimator.uses_vector_readings
        gated = getattr(estimator, "gate_probability", None) is not None
        if (not needs_vectors or getattr(module, "VECTOR_READINGS", False)) and \
                (not gated or getattr(module, "GATING", False)):
            return "kernel"
    if name in complementary.NAMES and type(estimator).__module__ == "estimators.complementary":
        return "compiled"
    if hasattr(estimator, "run_batch"):
        return "batch"
    return "per-run"


def run_recorded(estimator, omega_meas_radps: np.ndarray, vectors=(), *,
                 innovations: bool = False) -> RecordedRun:
    """``estimator`` (reset first, as ``run`` resets it) over the recorded
    rates ``(N, 3)`` and vector readings
    (:class:`sensors.vector.VectorReadings`), by :func:`path_of`'s path;
    with ``innovations``, a filter's innovation likelihood sums too
    (:attr:`RecordedRun.likelihood`, the kernel's or the per-run filter's
    ``innovation_sums``: the same numbers); an offline estimator's field
    timed first where it asks (:func:`field_timed`)."""
    omega = np.ascontiguousarray(checked_rates(omega_meas_radps))  # before any path reads it
    vectors, timing = field_timed(estimator, omega, checked_vector_record(vectors, len(omega)))
    run = _on_path(estimator, omega, vectors, innovations)
    return run if timing is None else replace(run, magnetometer_delay_s=timing.delay_s)


def _on_path(estimator, omega: np.ndarray, vectors: tuple, innovations: bool) -> RecordedRun:
    """:func:`run_recorded` once its readings are as the estimator reads them."""
    path = path_of(estimator, vectors)
    estimator.reset()
    if path == "kernel" and isinstance(estimator, MekfSmoother):
        return _smoothed(estimator, omega, vectors)
    if path == "kernel":
        run, record, _ = _kernel_record(estimator, omega, vectors, innovations=innovations)
        sums = record.likelihood[0, 0]
        covariance = (attitude_covariances(record.variances[0, 0])
                      if getattr(kernel(estimator.name), "REPORTS_COVARIANCE", False) else None)
        return replace(run, likelihood=(float(sums[0]), int(sums[1])) if innovations else None,
                       attitude_covariance=covariance)
    if path == "compiled" and _frame_learnt(estimator, vectors):
        from benchmarks.engine.kernels import complementary
        acc, has_acc, mag, has_mag = _channels(vectors, len(omega))
        states = complementary.run(estimator, omega, acc, has_acc, mag, has_mag)
        return _finished(estimator.in_reference_frame(quat_multiply(NWU_TO_ENU, states)), path)
    if path == "compiled":
        path = "per-run"
    if path == "batch":
        estimates = estimator.run_batch(omega, vectors)
        if estimates is not None:
            return replace(_finished(np.asarray(estimates, dtype=float), path),
                           rejected=dict(getattr(estimator, "rejected", {})))
        path = "per-run"
    logged = innovations and hasattr(estimator, "log_innovations")
    if logged:
        estimator.log_innovations = True
    estimates, covariance = _per_run(estimator, omega, vectors)
    sums = estimator.innovation_sums if logged else None
    return RecordedRun(estimates=estimates, diverged_step=estimator.diverged_step,
                       rejected=dict(estimator.rejected), path=path,
                       likelihood=(sums["log_det"] + sums["nis"], sums["updates"])
                       if logged else None, attitude_covariance=covariance)


def _per_run(estimator, omega: np.ndarray, vectors) -> tuple:
    """The per-run path: ``(estimates, attitude covariances or None)``. A
    class that runs a record step by step as the base class does (or the
    smoother) is tracked, keeping each step's covariance where it has one;
    any other's own ``run`` is called."""
    n = len(omega)
    star, available = np.tile(IDENTITY, (n, 1)), np.zeros(n, dtype=bool)
    if isinstance(estimator, MekfSmoother) or type(estimator).run is RecordRuns.run:
        trace = estimator.track(omega, star, available, vectors=vectors)
        return trace.quat, trace.attitude_covariance
    return estimator.run(omega, star, available, vectors=vectors), None


def _frame_learnt(estimator, vectors) -> bool:
    """Whether the compiled loop can take the per-run class's frame: the
    turn by the declination (:class:`estimators.complementary.MagneticFrame`)
    learnt before the first sample, as the per-run step learns it when the
    first sample has a magnetometer reading; or no turn at all."""
    field = next((v for v in vectors if v.sensor == "magnetometer" and v.available.any()), None)
    if field is None:
        return True
    first = int(np.argmax(field.available))
    turned = estimator.learn_frame(field.reference[first]) if first == 0 else \
        declination_turn(field.reference[first]) is not None
    return first == 0 or not turned


def _finished(estimates: np.ndarray, path: str) -> RecordedRun:
    """The estimates NaN from the first sample that is not finite, which is
    where the per-run path stops (``AttitudeEstimator.state_is_finite``)."""
    lost = ~np.isfinite(estimates).all(axis=1)
    first = int(np.argmax(lost)) if lost.any() else None
    if first is not None:
        estimates = estimates.copy()
        estimates[first:] = np.nan
    return RecordedRun(estimates=estimates, diverged_step=first, path=path)


def _channels(vectors, n: int) -> tuple:
    """The accelerometer's and magnetometer's readings and flags over the
    ``n`` samples, zeros and False where a sensor is absent."""
    found = {v.sensor: v for v in vectors}
    out = []
    for name in ("accelerometer", "magnetometer"):
        v = found.get(name)
        out += ([np.zeros((n, 3)), np.zeros(n, dtype=bool)] if v is None else
                [np.ascontiguousarray(v.body, dtype=float),
                 np.ascontiguousarray(v.available, dtype=bool)])
    return tuple(out)


def with_covariance(estimator, omega: np.ndarray, vectors) -> tuple:
    """``estimator`` (with a six-state kernel: the MEKF's) over a recording
    through its kernel: its :class:`RecordedRun`, and each output's bias
    ``(N, 3)`` and ``(N, 6, 6)`` covariance (what :mod:`estimators.smoother`
    fuses)."""
    run, record, _ = _kernel_record(estimator, np.ascontiguousarray(omega, dtype=float),
                                    tuple(vectors), full_state=True)
    kept = record.variances[0, 0]
    return run, kept[:, 42:45].copy(), kept[:, 6:42].reshape(-1, 6, 6).copy()


def _smoothed(smoother, omega: np.ndarray, vectors) -> RecordedRun:
    """:meth:`estimators.smoother.MekfSmoother.track` on a recording: both
    passes through the MEKF's kernel, fused by the smoother's own function."""
    forward_filter = smoother.pass_filter()
    forward, bias_f, covariance_f = with_covariance(forward_filter, omega, vectors)
    forward_filter.q_hat, forward_filter.beta_hat = forward.estimates[-1].copy(), bias_f[-1]
    backward_filter = smoother.pass_filter(backward_from=forward_filter)
    backward, bias_b, covariance_b = with_covariance(
        backward_filter, reversed_rates(omega, smoother.rate_interpolation),
        reversed_readings(vectors))
    quat, _, covariance = fuse((forward.estimates, bias_f, covariance_f),
                               (backward.estimates[::-1], bias_b[::-1], covariance_b[::-1]))
    return RecordedRun(estimates=quat, rejected=forward.rejected, path="kernel",
                       diverged_step=diverged_step(forward.diverged_step,
                                                   backward.diverged_step, len(omega)),
                       attitude_covariance=covariance[:, :3, :3].copy())


def attitude_covariances(kept: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` from a kernel's kept attitude variances ``(N, ≥ 6)``:
    the diagonal, then the xy, xz and yz terms (:func:`~benchmarks.engine.
    kernels.common.keep_variances`)."""
    covariance = np.empty((len(kept), 3, 3))
    for (i, j), column in zip(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)), range(6)):
        covariance[:, i, j] = covariance[:, j, i] = kept[:, column]
    return covariance


def _kernel_record(estimator, omega: np.ndarray, vectors, full_state: bool = False,
                   innovations: bool = False) -> tuple:
    """One run of the estimator's kernel over one block, the recording (its
    innovations' likelihood summed with ``innovations``): the run, and the
    kernel's record and state."""
    from benchmarks.engine.results import new_record
    from benchmarks.engine.kernels.common import Block
    from benchmarks.engine.kernels.sensors import SensorState
    module = kernel(estimator.name)
    used = vectors if estimator.uses_vector_readings else ()
    n = len(omega)
    record = new_record((estimator.name,), 1, n, True, innovations, n, 0, False, 0, len(used),
                        full_state=full_state)
    block = Block(
        k0=0, steps=n, last_step=n - 1, dt=float(estimator.dt),
        q_true=np.tile(IDENTITY, (n, 1)), omega_true=omega,
        gyro_std=np.zeros(1), gyro_normals=np.zeros((1, n, 3)), bias_model=np.zeros(5),
        gyro_scale=np.zeros((3, 3)), has_scale=False, has_bias=False,
        rotation_model=True, star_std=np.zeros(1), steps_between=np.ones(1, dtype=np.int64),
        star_normals=np.zeros((1, n + 1, 3)), sigma_rad=np.zeros(3), sensor_to_body=np.eye(3),
        canonical=False, outage=np.ones(n, dtype=bool), dropout_probability=0.0,
        dropout_uniforms=np.zeros((1, 0)),
        **_vector_arrays(used, n))
    state = module.initial_state([estimator])
    module.advance(block, SensorState(bias=np.zeros((1, 6)), bias_last=np.zeros((1, 3))),
                   state, record, 0)
    diverged = int(record.diverged[0, 0])
    rejected = {v.sensor: int(count) for v, count in zip(used, record.rejected[0, 0]) if count}
    return RecordedRun(estimates=record.traces[0, 0], diverged_step=None if diverged < 0
                       else diverged, rejected=rejected, path="kernel"), record, state


def _vector_arrays(vectors, n: int) -> dict:
    """The ``Block.vector_*`` arrays of one run from recorded readings."""
    count = len(vectors)
    arrays = dict(vector_body=np.zeros((1, n, count, 3)),
                  vector_reference=np.zeros((n, count, 3)),
                  vector_variance=np.zeros((1, n, count)),
                  vector_available=np.zeros((1, n, count), dtype=bool),
                  vector_dof=np.array([v.dof for v in vectors], dtype=np.int64),
                  vector_magnetic=np.array([v.sensor == "magnetometer" for v in vectors],
                                           dtype=bool),
                  vector_gravity=np.array([v.sensor == "accelerometer" for v in vectors],
                                          dtype=bool),
                  vector_known=np.array([getattr(v, "reference_known", True) for v in vectors],
                                        dtype=bool))
    for s, v in enumerate(vectors):
        arrays["vector_body"][0, :, s] = v.body
        arrays["vector_reference"][:, s] = v.reference
        arrays["vector_variance"][0, :, s] = v.variance
        arrays["vector_available"][0, :, s] = v.available
    return arrays
