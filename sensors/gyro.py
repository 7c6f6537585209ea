r"""Rate gyro: the standard (Farrenkopf) model, of which the workshop gyro is the special case.

The continuous model (Markley & Crassidis 2014, §4.7.1, eqs. 4.31–4.32;
Farrenkopf 1978) is

.. math:: \tilde\omega = (I_3 + K)\,\omega + \beta + \eta_v, \qquad
          \dot\beta = \eta_u,

with angle random walk (ARW) density :math:`\sigma_v` (rad/√s), bias rate
random walk (RRW) density :math:`\sigma_u` (rad/s^{3/2}) and a small 3×3
scale-factor-and-misalignment matrix :math:`K`. Sampled every
:math:`\Delta t`, the exact discretisation (Markley & Crassidis 2014,
§6.4.1, eqs. 6.92–6.93; Crassidis & Markley 2003, eq. 52) is

.. math::

    \beta_{k+1} = \beta_k + \sigma_u \Delta t^{1/2}\, N_{u,k}, \qquad
    \tilde\omega_k = (I_3 + K)\,\omega_k + \tfrac12(\beta_k + \beta_{k+1})
      + \Bigl(\frac{\sigma_v^2}{\Delta t} + \frac{\sigma_u^2 \Delta t}{12}\Bigr)^{1/2} N_{v,k},

with :math:`N_{v,k}, N_{u,k}` independent standard normal 3-vectors. The
reading :math:`\tilde\omega_k` is the average rate over the step from
:math:`t_k` to :math:`t_{k+1}` (the step the estimators propagate over), so it
uses the bias at both ends of the step.

**What the rate is.** ``sampling="sample"`` (the workshop's) reads the true
rate :math:`\omega(t_k)` at the step's start. Real gyros integrate: a rate
integrating gyro reports the angle increment over the sample interval, so
``sampling="average"`` reads the average rate over the step,
:math:`\bar\omega_k = \theta_k / \Delta t` with :math:`\theta_k` the rotation
vector of :math:`q(t_k)^{-1} \otimes q(t_{k+1})` (body frame). A filter that
propagates :math:`\hat q_{k+1} = \hat q_k \otimes \exp(\tfrac12 \tilde\omega_k \Delta t)`
(the MEKF's and USQUE's exact constant-rate step) then reproduces the truth
exactly without noise; with ``"sample"`` it errs by about
:math:`\tfrac12 \dot\omega \Delta t^2` a step, an error no filter's ``Q``
models, which grows with the tumble and the sample interval (at 2.5 °/s and
5 Hz it makes the MEKF optimistic). :func:`average_rates` computes it.

**Bias instability.** Beside the random walk, the bias may hold a first-order
Gauss–Markov part :math:`b` of standard deviation :math:`\sigma_b` and
correlation time :math:`\tau` (Markley & Crassidis 2014, §3.6 on the
Gauss–Markov process; IEEE Std 952-1997, Annex C, for the bias instability
of a datasheet), discretised exactly:

.. math:: b_{k+1} = \phi\, b_k + \sigma_b \sqrt{1 - \phi^2}\, N_{b,k},
          \qquad \phi = e^{-\Delta t/\tau}, \qquad b_0 \sim \mathcal N(0, \sigma_b^2 I_3),

so its autocorrelation is :math:`\sigma_b^2 e^{-|t|/\tau}` and it starts
stationary. The bias is then :math:`\beta_k = \beta_0 + (\text{random walk})_k + b_k`.
A filter whose bias model is a random walk is told it through
:func:`equivalent_bias_random_walk` (the Gauss–Markov process's driving
noise :math:`\sigma_u^2 = 2\sigma_b^2/\tau`, exact over times short against
:math:`\tau`, pessimistic beyond). :mod:`sensors.noise` converts the
datasheet's units (°/h bias instability, °/s/√Hz noise density).

The noise power :math:`p` of the workshop (Simulink's band-limited white
noise, variance :math:`p/\Delta t` per sample) *is* :math:`\sigma_v^2`. With
:math:`\sigma_u = 0`, :math:`\beta_0 = 0` and :math:`K = 0` the model is the
workshop gyro of the workshop model, "Sensors", :math:`\tilde\omega_k = \omega_k + n_k`,
:math:`n_k \sim \mathcal N(0, (p/\Delta t) I_3)`, and draws exactly the same
numbers (3 normals per step; with :math:`\sigma_u > 0` it draws 6 per step,
:math:`[N_{v,k}, N_{u,k}]`, in row order; with a Gauss–Markov part it first
draws :math:`b_0`'s 3 normals, then 3 more per step after those).
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.quaternion import quat_conjugate, quat_multiply, rotvec_from_quat
from dynamics.validation import InvalidParameterError, finite_number, finite_vector, one_of

#: What a reading's rate is: the true rate at the step's start (the
#: workshop's), or the average over the step (an integrating gyro's).
SAMPLINGS = ("sample", "average")
#: The largest bias (each axis, rad/s, about 570 °/s) and bias instability
#: σ_b a gyro may have: far beyond any gyro's (a MEMS gyro's is a fraction
#: of a degree per second), and a hundredth of the ±1000 rad/s an estimator
#: accepts, so that readings stay readings.
MAX_BIAS_RADPS = 10.0
#: The largest bias rate random walk σ_u, rad/s^1.5 (a MEMS gyro's is about
#: 1e-4; beyond this the bias is noise in a few seconds).
MAX_BIAS_RANDOM_WALK = 1.0


def average_rates(q_true: np.ndarray, dt: float, q_after=None, last_rate=None) -> np.ndarray:
    """The average body rate over each step, ``(N, 3)`` rad/s: the rotation
    vector of ``q_k⁻¹ ⊗ q_{k+1}`` over ``dt``.

    The last row needs the attitude one step after the record, ``q_after``;
    without it the last row is ``last_rate`` (the sampled rate there: no
    estimate of the record depends on the last reading, which only
    propagates past its end).
    """
    q_true = np.asarray(q_true, dtype=float)
    following = q_true[1:] if q_after is None else np.vstack([q_true[1:], q_after])
    increments = quat_multiply(quat_conjugate(q_true[:len(following)]), following)
    rates = rotvec_from_quat(increments) / dt
    if q_after is None:
        rates = np.vstack([rates, np.reshape(last_rate, (1, 3))])
    return rates


def equivalent_bias_random_walk(bias_random_walk: float, instability_radps: float,
                                correlation_time_s: float) -> float:
    """``σ_u`` (rad/s^{3/2}) a random-walk bias model takes for a bias with a
    random walk ``σ_u`` and a Gauss–Markov part ``(σ_b, τ)``:
    ``√(σ_u² + 2 σ_b²/τ)``, the Gauss–Markov process's driving noise (exact
    over times short against ``τ``).

    >>> round(equivalent_bias_random_walk(0.0, 1e-5, 200.0), 9)
    1e-06
    """
    if instability_radps == 0.0:
        return bias_random_walk
    return math.sqrt(bias_random_walk ** 2 + 2.0 * instability_radps ** 2 / correlation_time_s)


def _check_at_most(name: str, number: float, limit: float, unit: str, given=None) -> None:
    """Refuse a bias setting beyond what any gyro has (the limits above)."""
    if number > limit:
        raise InvalidParameterError(name, number if given is None else given,
                                    f"must be at most {limit:g} {unit}, beyond any gyro's")


def scale_misalignment_matrix(name: str, value) -> np.ndarray | None:
    """A finite 3x3 matrix ``K``; ``None`` (or all zeros) means no scale or misalignment."""
    if value is None:
        return None
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, "must be a 3x3 matrix") from None
    if array.shape != (3, 3):
        raise InvalidParameterError(name, value, "must be a 3x3 matrix")
    if not np.all(np.isfinite(array)):
        raise InvalidParameterError(name, value, "must be finite")
    if np.abs(array).max() >= 0.1:
        raise InvalidParameterError(name, value, "must be small: every entry below 0.1 "
                                    "(scale factors and misalignments are parts per million "
                                    "to a few per cent)")
    return array if np.any(array) else None


class Gyro:
    """A three-axis rate gyro sampled every ``dt`` seconds.

    Parameters
    ----------
    noise_power : float
        ``σ_v²`` in rad²/s: the workshop's noise power, the square of the
        angle random walk density (see :mod:`sensors.noise` for deg/√h).
    dt : float
        Sample time in seconds.
    bias_random_walk : float
        ``σ_u`` in rad/s^{3/2}, the bias's rate random walk (0: a constant bias).
    initial_bias_radps : (3,) array-like
        ``β_0`` in rad/s.
    scale_misalignment : (3, 3) array-like or None
        ``K``, the scale factor errors on its diagonal and misalignments off it.
    sampling : {"sample", "average"}
        The true rate at the step's start (the workshop's) or its average over
        the step (see the module docstring); :meth:`true_rates` makes it.
    bias_instability_radps : float
        ``σ_b`` in rad/s of the bias's Gauss–Markov part (0: none).
    bias_correlation_time_s : float
        ``τ`` in seconds of that part.
    """

    def __init__(self, noise_power: float, dt: float, *, bias_random_walk: float = 0.0,
                 initial_bias_radps=(0.0, 0.0, 0.0), scale_misalignment=None,
                 sampling: str = "sample", bias_instability_radps: float = 0.0,
                 bias_correlation_time_s: float = 3600.0):
        self.noise_power = finite_number("gyro_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.bias_random_walk = finite_number("gyro_bias_random_walk", bias_random_walk,
                                              minimum=0.0)
        self.initial_bias_radps = finite_vector("gyro_initial_bias_radps", initial_bias_radps, 3)
        _check_at_most("gyro_initial_bias_radps", np.abs(self.initial_bias_radps).max(),
                       MAX_BIAS_RADPS, "rad/s on every axis", initial_bias_radps)
        _check_at_most("gyro_bias_random_walk", self.bias_random_walk, MAX_BIAS_RANDOM_WALK,
                       "rad/s^1.5")
        self.scale_misalignment = scale_misalignment_matrix("gyro_scale_misalignment",
                                                            scale_misalignment)
        self.sampling = one_of("gyro_sampling", sampling, SAMPLINGS)
        self.bias_instability_radps = finite_number(
            "gyro_bias_instability_radps", bias_instability_radps, minimum=0.0)
        _check_at_most("gyro_bias_instability_radps", self.bias_instability_radps,
                       MAX_BIAS_RADPS, "rad/s")
        self.bias_correlation_time_s = finite_number(
            "gyro_bias_correlation_time_s", bias_correlation_time_s, strictly_positive=True)
        self.std_radps = self.reading_std(self.noise_power, self.dt, self.bias_random_walk)
        self.bias_step_std = self.bias_random_walk * math.sqrt(self.dt)
        if not math.isfinite(2.0 * self.bias_instability_radps ** 2
                             / self.bias_correlation_time_s):
            raise InvalidParameterError(
                "gyro_bias_correlation_time_s", bias_correlation_time_s,
                f"makes the Gauss-Markov bias's driving noise 2 σ_b²/τ overflow with σ_b = "
                f"{self.bias_instability_radps:g} rad/s; give a longer correlation time")
        #: The Gauss–Markov part's step: b ← φ b + σ_b √(1 - φ²) N.
        self.markov_phi = math.exp(-self.dt / self.bias_correlation_time_s)
        self.markov_step_std = self.bias_instability_radps * math.sqrt(
            -math.expm1(-2.0 * self.dt / self.bias_correlation_time_s))

    @property
    def filter_bias_random_walk(self) -> float:
        """``σ_u`` a filter with a random-walk bias should assume (see
        :func:`equivalent_bias_random_walk`)."""
        return equivalent_bias_random_walk(self.bias_random_walk, self.bias_instability_radps,
                                           self.bias_correlation_time_s)

    def true_rates(self, q_true: np.ndarray, omega_true_radps: np.ndarray,
                   q_after=None) -> np.ndarray:
        """The rates this gyro's readings are made of, ``(N, 3)``: the sampled
        true rates, or their averages over each step (:func:`average_rates`)."""
        if self.sampling == "sample":
            return np.asarray(omega_true_radps, dtype=float)
        return average_rates(q_true, self.dt, q_after, np.asarray(omega_true_radps)[-1])

    @staticmethod
    def reading_std(noise_power: float, dt: float, bias_random_walk: float) -> float:
        """Per-sample white-noise σ, rad/s: ``√(σ_v²/Δt + σ_u²Δt/12)``; with
        ``σ_u = 0`` exactly the workshop's ``√(p/Δt)``."""
        return math.sqrt(noise_power / dt + bias_random_walk ** 2 * dt / 12.0)

    @property
    def normals_per_step(self) -> int:
        """Standard normals drawn per sample: 3, 3 more with a bias random
        walk and 3 more with a Gauss–Markov part."""
        return 3 + 3 * (self.bias_random_walk > 0) + 3 * (self.bias_instability_radps > 0)

    def measure(self, omega_true_radps: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(N, 3)`` in rad/s for true rates ``(N, 3)`` (see :meth:`measure_with_bias`)."""
        return self.measure_with_bias(omega_true_radps, rng)[0]

    def measure_with_bias(self, omega_true_radps: np.ndarray, rng: np.random.Generator
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Readings ``(N, 3)`` and the true bias ``β_k`` ``(N, 3)``, both rad/s.

        Draws (with a Gauss–Markov part, first ``b_0``'s 3 and then)
        ``N × normals_per_step`` standard normals from ``rng`` in row order,
        so the same generator state gives the same noise whatever else is
        simulated.
        """
        omega_true = np.asarray(omega_true_radps, dtype=float)
        if not self.has_bias_model:
            # The workshop gyro, exactly: ω + σ n.
            noise = rng.standard_normal(omega_true.shape)
            return omega_true + self.std_radps * noise, np.zeros_like(omega_true)
        markov_start = (self.bias_instability_radps * rng.standard_normal(3)
                        if self.bias_instability_radps > 0 else None)
        normals = rng.standard_normal((len(omega_true), self.normals_per_step))
        rates = omega_true
        if self.scale_misalignment is not None:
            rates = rates + omega_true @ self.scale_misalignment.T
        # β_k for k = 0 … N (one more than the samples: the end of the last step).
        steps = (self.bias_step_std * normals[:, 3:6] if self.bias_random_walk > 0
                 else np.zeros((len(omega_true), 3)))
        bias = self.initial_bias_radps + np.concatenate(
            [np.zeros((1, 3)), np.cumsum(steps, axis=0)], axis=0)
        if markov_start is not None:
            bias = bias + self._markov_sequence(markov_start, normals[:, -3:])
        rates = rates + 0.5 * (bias[:-1] + bias[1:])
        return rates + self.std_radps * normals[:, :3], bias[:-1]

    def _markov_sequence(self, start: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """The Gauss–Markov part ``b_0 … b_N`` ``(N + 1, 3)`` from ``b_0`` and
        the steps' normals (a first-order recursion: scipy's ``lfilter``)."""
        from scipy.signal import lfilter
        drive = np.vstack([start, self.markov_step_std * normals])
        return lfilter([1.0], [1.0, -self.markov_phi], drive, axis=0)

    @property
    def has_bias_model(self) -> bool:
        """True unless this is the workshop gyro (no bias, no scale or misalignment)."""
        return (self.bias_random_walk > 0 or bool(np.any(self.initial_bias_radps))
                or self.scale_misalignment is not None or self.bias_instability_radps > 0)
