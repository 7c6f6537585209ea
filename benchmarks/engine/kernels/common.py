r"""What every engine kernel shares: the error bookkeeping (streaming
statistics, the median histogram, traces, divergence), the NEES, the
gates and the health checks (the small linear algebra and the quaternion
steps are :mod:`benchmarks.engine.kernels.algebra`).

Each formula is the same, in the same order, as its reference on the
per-run path (named in each docstring), so the kernels reproduce it to
rounding. Division by zero follows numpy's IEEE rules
(``error_model="numpy"``), as on the per-run path, which also spares a check
on every division.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels.algebra import gauss_jordan, log_error, quadratic_form


class Record(NamedTuple):
    """What the kernels write, one row per estimator run (``rows`` × B):
    the streaming statistics, the step each run diverged (-1: never), the
    median histogram, and optionally traces, sampled errors, the NEES and
    NIS sums and the health counters."""

    stats: np.ndarray            # (rows, B, N_ACCUMULATORS)
    diverged: np.ndarray         # (rows, B) int64
    hist: np.ndarray             # (rows, B, bins) uint32
    hist_first_bits: int
    traces: np.ndarray           # (rows, B, N, 4), or (rows, 0, 0, 4) when not kept
    keep_traces: bool
    variances: np.ndarray        # (rows, B, N, 3): with traces, the attitude variances
    error_every: int             # keep the error every that many steps (0: not)
    error_samples: np.ndarray    # (rows, B, S)
    consistency: bool            # stream NEES and NIS
    nees_every: int
    settle: int                  # first step of the NEES time average
    nees_samples: np.ndarray     # (rows, B, S)
    nees_sum: np.ndarray         # (rows, B)
    nis_sum: np.ndarray          # (rows, B)
    nis_count: np.ndarray        # (rows, B)
    #: Per run, over every applied update (tracker and vectors): the sum of
    #: ln det S + yᵀ S⁻¹ y and the number of updates (the likelihood objective).
    likelihood: np.ndarray       # (rows, B, 2)
    check_health: bool
    health: np.ndarray           # (rows, B, N_HEALTH), or (rows, 0, N_HEALTH)
    #: Per run and vector sensor (the block's order): the readings gating
    #: rejected (estimators.base: ``rejected``), by the kernels that gate.
    rejected: np.ndarray         # (rows, B, S) int64


class Block(NamedTuple):
    """A block of ``steps`` steps from step ``k0``, as every estimator kernel
    reads it: the truth, and the noise its sensors' readings are made of
    (:mod:`benchmarks.engine.kernels.sensors`), one row per run. Flat: numba's
    parallel loops, which the kernels had, took no tuple nested in a tuple."""

    k0: int                      # the first step
    steps: int
    last_step: int               # the run's last step (N - 1)
    dt: float
    q_true: np.ndarray           # (T, 4)
    omega_true: np.ndarray       # (T, 3) rad/s
    # The gyro (sensors.Gyro): per-sample σ, this block's normals (white
    # noise, then the bias walk's and the Gauss–Markov part's), the bias model, K = scale
    # and misalignment.
    gyro_std: np.ndarray         # (B,) rad/s
    gyro_normals: np.ndarray     # (B, T, 3, 6 or 9)
    bias_model: np.ndarray       # (5,) the walk's and the Gauss–Markov part's (sensors.py)
    gyro_scale: np.ndarray       # (3, 3)
    has_scale: bool
    has_bias: bool
    # The star tracker (sensors.StarTracker or RotationStarTracker): readings
    # at k ≡ 0 (mod m), this block's normals taken in order, and the uniforms
    # of its dropouts.
    rotation_model: bool
    star_std: np.ndarray         # (B,) per-component σ of the workshop model
    steps_between: np.ndarray    # (B,) int64
    star_normals: np.ndarray     # (B, readings in this block, 3 or 4)
    sigma_rad: np.ndarray        # (3,) the rotation model's σ per sensor axis
    sensor_to_body: np.ndarray   # (3, 3)
    canonical: bool
    outage: np.ndarray           # (T,) bool
    dropout_probability: float
    dropout_uniforms: np.ndarray  # (B, readings in this block)
    # The vector sensors (sensors.vector), S of them in the scenario's order,
    # measured on the host by the per-run path's classes (engine.vectors):
    # each run's readings at each step of the block, the shared reference
    # vectors, and each sensor's degrees of freedom (for its gate).
    vector_body: np.ndarray       # (B, T, S, 3)
    vector_reference: np.ndarray  # (T, S, 3)
    vector_variance: np.ndarray   # (B, T, S) σ² per axis
    vector_available: np.ndarray  # (B, T, S) bool
    vector_dof: np.ndarray        # (S,) int64
    vector_magnetic: np.ndarray   # (S,) bool: a magnetometer (its norm tested, passes_norm)
    vector_gravity: np.ndarray    # (S,) bool: an accelerometer (the IMU models')
    vector_known: np.ndarray      # (S,) bool: its reference is the vector, not only its azimuth


#: Per-run streaming accumulators: Welford mean and M2, max, final value.
MEAN, M2, MAX, FINAL = 0, 1, 2, 3
N_ACCUMULATORS = 4
#: Histogram bins keep 7 mantissa bits: 128 bins per octave of error.
HISTOGRAM_SHIFT = 52 - 7
RAD_TO_DEG = 180.0 / math.pi

# fdlibm's e_acos.c coefficients (Sun Microsystems, 1993): asin(√z)/√z - 1 ≈ z p(z)/q(z).
_PS0 = 1.66666666666666657415e-01
_PS1 = -3.25565818622400915405e-01
_PS2 = 2.01212532134862925881e-01
_PS3 = -4.00555345006794114027e-02
_PS4 = 7.91534994289814532176e-04
_PS5 = 3.47933107596021167570e-05
_QS1 = -2.40339491173441421878e+00
_QS2 = 2.02094576023350569471e+00
_QS3 = -6.88283971605453293030e-01
_QS4 = 7.70381505559019352791e-02
HIGH_WORD_MASK = np.int64(-4294967296)   # clears the low 32 bits of a double


@njit(cache=True, inline="always", error_model="numpy")
def acos(x, bits, bits_int):
    """arccos(x) for 0 <= x <= 1, within 1 ulp of the C library's.

    The attitude error needs one arccos per step per estimator, and the C
    library's call was a fifth of the kernel's time. Nearly all attitude
    errors are below 120°, i.e. x > 0.5, where fdlibm's branch
    acos(x) = 2 asin(√((1 - x)/2)) with its rational approximation is
    inlined here; elsewhere the library is called.
    """
    if x >= 1.0:
        return 0.0
    if x <= 0.5:
        return math.acos(x)
    z = (1.0 - x) * 0.5
    s = math.sqrt(z)
    bits[0] = s
    bits_int[0] = bits_int[0] & HIGH_WORD_MASK
    return acos_near_one(z, s, bits[0])


@njit(cache=True, inline="always", error_model="numpy")
def acos_near_one(z, s, df):
    """fdlibm's acos(x) for x > 0.5 from z = (1 - x)/2, s = √z and ``df``,
    s with its low 32 bits cleared (:data:`HIGH_WORD_MASK`)."""
    c = (z - df * df) / (s + df)
    p = z * (_PS0 + z * (_PS1 + z * (_PS2 + z * (_PS3 + z * (_PS4 + z * _PS5)))))
    q = 1.0 + z * (_QS1 + z * (_QS2 + z * (_QS3 + z * _QS4)))
    return 2.0 * (df + (p / q) * s + c)


@njit(cache=True, inline="always", error_model="numpy")
def error_arrays(record, row):
    """Estimator ``row``'s slices of the record that :func:`record_error` and
    the health checks write, taken out of the tuple (before a kernel's
    loop over its runs: see the kernels package's docstring)."""
    return (record.stats[row], record.hist[row], record.hist_first_bits, record.traces[row],
            record.keep_traces, record.error_every, record.error_samples[row],
            record.diverged[row], record.check_health, record.health[row])


@njit(cache=True, inline="always", error_model="numpy")
def nees_arrays(record, row):
    """Estimator ``row``'s NEES and NIS accumulators and its kept variances,
    likewise (what a kernel that reports a covariance writes)."""
    return (record.consistency, record.nees_every, record.settle, record.nees_samples[row],
            record.nees_sum[row], record.nis_sum[row], record.nis_count[row],
            record.variances[row], record.likelihood[row])


@njit(cache=True, error_model="numpy")
def mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples):
    """Step ``k`` is where ``run`` stopped being finite, unless it already had:
    from ``k`` on its estimate and error are NaN
    (estimators.base.AttitudeEstimator.state_is_finite)."""
    if diverged[run] < 0:
        diverged[run] = k
    if keep_traces:
        for i in range(4):
            traces[run, k, i] = math.nan
    if error_every and k % error_every == 0:
        samples[run, k // error_every] = math.nan


@njit(cache=True, inline="always", error_model="numpy")
def finite_state(q, n_q, P, n):
    """The divergence test of estimators.base.AttitudeEstimator.state_is_finite:
    the sum of the first ``n_q`` state entries and the trace of the leading
    ``n`` x ``n`` covariance block are finite (a NaN or infinity anywhere in
    them makes its sum non-finite)."""
    total = 0.0
    for i in range(n_q):
        total += q[i]
    trace = 0.0
    for i in range(n):
        trace += P[i, i]
    return math.isfinite(total) and math.isfinite(trace)


@njit(cache=True, error_model="numpy")
def record_error(run, k, q_true_k, q, stats, hist, first_bits, traces, keep_traces,
                 error_every, samples, diverged, bits, bits_int):
    """Error of estimate ``q`` at step ``k``, folded into the run's accumulators
    (estimator ``row``'s slices of the :class:`Record`: ``stats``, ``hist``,
    ``traces``, ``samples``, ``diverged``), kept every ``error_every`` steps if
    that is not 0. A non-finite estimate marks the run diverged
    (:func:`mark_diverged`): its error is NaN, never the 0 that
    ``min(1, NaN)`` would give."""
    dot = abs(q_true_k[0] * q[0] + q_true_k[1] * q[1] + q_true_k[2] * q[2]
              + q_true_k[3] * q[3])
    if diverged[run] >= 0 or not math.isfinite(dot):
        mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
        return
    error = 2.0 * acos(min(1.0, dot), bits, bits_int) * RAD_TO_DEG
    fold_error(run, k, error, stats, hist, first_bits, error_every, samples, bits, bits_int)
    if keep_traces:
        for i in range(4):
            traces[run, k, i] = q[i]


@njit(cache=True, inline="always", error_model="numpy")
def welford(mean, m2, maximum, error, inv_count, first):
    """The running mean, M2 and maximum with one more ``error``
    (``inv_count``: Welford's 1/n; ``first``: the run's first step)."""
    delta = error - mean
    mean = mean + delta * inv_count
    return mean, m2 + delta * (error - mean), error if error > maximum or first else maximum


@njit(cache=True, inline="always", error_model="numpy")
def fold_error(run, k, error, stats, hist, first_bits, error_every, samples, bits,
               bits_int):
    """The error at step ``k`` (degrees) folded into the run's Welford mean
    and M2, maximum and final value, then counted (:func:`count_error`)."""
    stats[run, MEAN], stats[run, M2], stats[run, MAX] = welford(
        stats[run, MEAN], stats[run, M2], stats[run, MAX], error, 1.0 / (k + 1), k == 0)
    stats[run, FINAL] = error
    count_error(run, k, error, hist, first_bits, error_every, samples, bits, bits_int)


@njit(cache=True, inline="always", error_model="numpy")
def count_error(run, k, error, hist, first_bits, error_every, samples, bits, bits_int):
    """The error at step ``k`` counted in the run's histogram, and kept every
    ``error_every`` steps (``bits``: one float of scratch, ``bits_int`` its
    int64 view)."""
    # Histogram bin from the float's bit pattern (exponent and top mantissa
    # bits), monotone in the error: a log-like binning without calling log.
    bits[0] = error
    index = (bits_int[0] >> HISTOGRAM_SHIFT) - first_bits + 1
    if index < 0:
        index = 0
    elif index >= hist.shape[1]:
        index = hist.shape[1] - 1
    hist[run, index] += 1
    if error_every and k % error_every == 0:
        samples[run, k // error_every] = error


# Inlined copies for the small kernels (the EKF's, dead reckoning's with and
# without resets), where inlining costs little compile time and spares a call
# a step (dead reckoning with resets, this and its prediction inlined: 61–64
# ns a run-step on one thread against 102, its cold compile 7.8 s against
# 8.1). The MEKF's and USQUE's kernels call them from several places: there
# inlining doubled their first compile (about a minute each on a cold
# machine) for no measured speed.
record_error_inlined = njit(cache=True, inline="always",
                            error_model="numpy")(record_error.py_func)
gauss_jordan_inlined = njit(cache=True, inline="always",
                            error_model="numpy")(gauss_jordan.py_func)


@njit(cache=True, error_model="numpy")
def nees(q_true_k, q, C, scratch):
    """eᵀ C⁻¹ e with e = log(q̂⁻¹ ⊗ q) the body-frame error of estimate ``q``
    and ``C`` its 3x3 covariance (benchmarks.metrics.nees)."""
    # The EKF's estimate is not unit: normalise it inside the log.
    e = log_error(q, q_true_k, math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    S = scratch[0]
    inverse = scratch[1]
    for i in range(3):
        for j in range(3):
            S[i, j] = C[i, j]
    gauss_jordan(S, inverse, 3)
    return quadratic_form(e, inverse, 3)


@njit(cache=True, inline="always", error_model="numpy")
def keep_variances(run, k, C, variances, keep_traces):
    """With traces, the output's 3x3 attitude covariance ``C`` (rad², body
    frame) at step ``k``: its diagonal (the per-axis ±3σ figures'), then its
    xy, xz and yz terms (a smoother's fusion, :mod:`estimators.smoother`)."""
    if keep_traces:
        for i in range(3):
            variances[run, k, i] = C[i, i]
        variances[run, k, 3] = C[0, 1]
        variances[run, k, 4] = C[0, 2]
        variances[run, k, 5] = C[1, 2]


#: The width of a trace's covariance row with the full state kept: the
#: attitude's 6 (diagonal, then xy, xz, yz), the 6x6 covariance, the bias.
FULL_STATE_WIDTH = 6 + 36 + 3


@njit(cache=True, inline="always", error_model="numpy")
def keep_output(run, k, last_step, q_true_k, out, beta, P, beta_last, P_last, variances,
                keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch):
    """What a six-state kernel keeps of the estimate ``out`` it outputs at step
    ``k`` (before or after the step's reading, as the filter outputs): the
    attitude variances with traces, the bias ``beta`` and ``P`` (6x6, or
    larger where the kernel keeps more states) at the last step for the
    final report, and the NEES."""
    keep_variances(run, k, P, variances, keep_traces)
    if keep_traces and variances.shape[2] == FULL_STATE_WIDTH:
        for i in range(6):
            for j in range(6):
                variances[run, k, 6 + 6 * i + j] = P[i, j]
        for i in range(3):
            variances[run, k, 42 + i] = beta[i]
    if k == last_step:
        for i in range(3):
            beta_last[run, i] = beta[i]
        for i in range(P_last.shape[1]):
            for j in range(P_last.shape[1]):
                P_last[run, i, j] = P[i, j]
    if streaming:
        fold_nees(run, k, nees(q_true_k, out, P, scratch), nees_every, settle, nees_samples,
                  nees_sum)


@njit(cache=True, inline="always", error_model="numpy")
def fold_innovation(run, nis, determinant, likelihood):
    """Add a gated reading's ln det S + NIS to the run's likelihood sums
    (a non-positive det S, a covariance gone bad, makes it infinite): the
    caller passes the gate's threshold for the NIS of a reading the gate
    rejected (:meth:`estimators.gating.InnovationGate.accepts`)."""
    likelihood[run, 0] += (math.log(determinant) if determinant > 0.0 else math.inf) + nis
    likelihood[run, 1] += 1.0


@njit(cache=True, inline="always", error_model="numpy")
def fold_nees(run, k, value, every, settle, samples, nees_sum):
    """Add a NEES value to the run's time average (from the settle step) and
    keep it at the sampled steps."""
    if k >= settle:
        nees_sum[run] += value
    if k % every == 0 and k // every < samples.shape[1]:
        samples[run, k // every] = value


def gate_thresholds(estimators) -> dict:
    """Each run's innovation gate, read off its per-run filter: ``gating``
    ``(B,)`` bool, and ``gate`` ``(B, 4)``, the χ² threshold of a reading of
    1, 2 or 3 degrees of freedom at its ``gate_probability``
    (:func:`estimators.gating.gate_threshold`; infinite where it does not gate)."""
    from estimators.gating import gate_threshold
    gate = np.full((len(estimators), 4), math.inf)
    for run, estimator in enumerate(estimators):
        if estimator.gate_probability is not None:
            gate[run, 1:] = [gate_threshold(estimator.gate_probability, dof) for dof in (1, 2, 3)]
    return {"gating": np.array([e.gate_probability is not None for e in estimators]),
            "gate": gate}


def gyro_errors(estimators) -> np.ndarray:
    """``(B, 3)``: each run's gyro model, read off its per-run filter: its
    σ_v², σ_u and S_s (``gyro_noise``, ``gyro_bias_random_walk``,
    ``gyro_scale_density``: :mod:`estimators.mekf`)."""
    return np.array([[e.gyro_noise, e.gyro_bias_random_walk, e.gyro_scale_density]
                     for e in estimators], dtype=float).reshape(-1, 3)


def norm_tolerances(estimators) -> np.ndarray:
    """Each run's magnetic norm tolerance, read off its per-run filter
    (``magnetic_norm_tolerance``; infinite where it does not test)."""
    return np.array([math.inf if getattr(e, "magnetic_norm_tolerance", None) is None
                     else float(e.magnetic_norm_tolerance) for e in estimators])


def rate_states(estimators) -> dict:
    """Each run's rate interpolation, read off its per-run filter
    (:mod:`estimators.sampled_rate`): ``trapezoid`` ``(B,)`` bool, and the
    last reading each run has taken (``rate_prev`` ``(B, 3)``, ``has_rate``
    ``(B,)``), which a trapezoidal filter propagates with at the next step."""
    count = len(estimators)
    modes = [getattr(e, "rate_interpolation", "hold") for e in estimators]
    return {"trapezoid": np.array([mode in ("trapezoid", "end") for mode in modes]),
            "rate_prev": np.zeros((count, 3)), "has_rate": np.zeros(count, dtype=bool),
            "end": np.array([mode == "end" for mode in modes])}


@njit(cache=True, inline="always", error_model="numpy")
def rate_arrays(state):
    """What a six-state kernel reads at every step besides its filter's
    arrays: its rate interpolation (:func:`rate_states`), and the IMU models'
    flag and arrays (``benchmarks.engine.kernels.imu.imu_state``), taken out
    of its state's tuple before the loop over the runs (read off the tuple
    inside the parallel loop the kernels had, the inlined gyro reading's
    writes to the IMU models' counts were lost)."""
    return (state.trapezoid, state.rate_prev, state.has_rate, state.end, state.imu_on,
            state.imu_counts, state.imu_detector, state.imu_rate_lp, state.imu_strapdown,
            state.imu_rotation, state.imu_table, state.imu_table_dt, state.imu_work)


@njit(cache=True, inline="always", error_model="numpy")
def trapezoid_rate(run, w, mean, trapezoid, rate_prev, has_rate, end):
    """For a filter that propagates at the next step
    (:class:`estimators.sampled_rate.SampledRate`, ``"trapezoid"`` or
    ``"end"``): the mean of the last reading and this one, ``w`` (or ``w``
    itself, at the step's end), into ``mean``; True if there was a last
    reading, so that the step just ended is propagated now, before this
    step's readings. The reading is kept for the next step."""
    if not trapezoid[run]:
        return False
    ready = has_rate[run]
    for i in range(3):
        if ready:
            mean[i] = w[i] if end[run] else 0.5 * (rate_prev[run, i] + w[i])
        rate_prev[run, i] = w[i]
    has_rate[run] = True
    return ready


@njit(cache=True, inline="always", error_model="numpy")
def passes_norm(body, reference, tolerance):
    """:meth:`estimators.gating.InnovationGate.passes_norm` of a magnetometer
    reading: |‖b‖ / ‖r‖ − 1| ≤ ``tolerance``, the same arithmetic."""
    ratio = math.sqrt(body[0] * body[0] + body[1] * body[1] + body[2] * body[2]) / math.sqrt(
        reference[0] * reference[0] + reference[1] * reference[1] + reference[2] * reference[2])
    return abs(ratio - 1.0) <= tolerance


#: Health counters per estimator and run (``run_batch(health=True)``): the
#: checks made, then how many found |q| off 1 by more than
#: :data:`NORM_TOLERANCE`, a covariance not symmetric to
#: :data:`SYMMETRY_TOLERANCE` of its largest diagonal entry, one not positive
#: definite (a Cholesky pivot <= 0), a NaN or infinity; then the largest
#: ||q| - 1| and the largest relative asymmetry seen.
CHECKS, NORM_OFF, ASYMMETRIC, NOT_POSITIVE_DEFINITE, NON_FINITE = 0, 1, 2, 3, 4
WORST_NORM, WORST_ASYMMETRY = 5, 6
N_HEALTH = 7
NORM_TOLERANCE = 1e-12
SYMMETRY_TOLERANCE = 1e-12


@njit(cache=True, error_model="numpy")
def check_health(q, unit, P, n, counts, factor):
    """Fold one check of estimate ``q`` (unit by design if ``unit``) and the
    leading ``n`` x ``n`` block of ``P`` (n = 0: no covariance) into ``counts``."""
    counts[CHECKS] += 1
    finite = True
    for i in range(4):
        if not math.isfinite(q[i]):
            finite = False
    if unit:
        deviation = abs(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1.0)
        if not deviation <= NORM_TOLERANCE:
            counts[NORM_OFF] += 1
        if deviation > counts[WORST_NORM]:
            counts[WORST_NORM] = deviation
    if n:
        scale = 0.0
        for i in range(n):
            scale = max(scale, abs(P[i, i]))
        asymmetry = 0.0
        for i in range(n):
            for j in range(n):
                if not math.isfinite(P[i, j]):
                    finite = False
                asymmetry = max(asymmetry, abs(P[i, j] - P[j, i]))
        relative = asymmetry / scale if scale > 0.0 else asymmetry
        if not relative <= SYMMETRY_TOLERANCE:
            counts[ASYMMETRIC] += 1
        if relative > counts[WORST_ASYMMETRY]:
            counts[WORST_ASYMMETRY] = relative
        # Cholesky of the symmetric part: positive definite iff every pivot > 0.
        for j in range(n):
            total = P[j, j]
            for m in range(j):
                total -= factor[j, m] * factor[j, m]
            if not total > 0.0:
                counts[NOT_POSITIVE_DEFINITE] += 1
                break
            factor[j, j] = math.sqrt(total)
            for i in range(j + 1, n):
                value = 0.5 * (P[i, j] + P[j, i])
                for m in range(j):
                    value -= factor[i, m] * factor[j, m]
                factor[i, j] = value / factor[j, j]
    if not finite:
        counts[NON_FINITE] += 1


