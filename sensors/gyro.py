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

The noise power :math:`p` of the workshop (Simulink's band-limited white
noise, variance :math:`p/\Delta t` per sample) *is* :math:`\sigma_v^2`. With
:math:`\sigma_u = 0`, :math:`\beta_0 = 0` and :math:`K = 0` the model is the
workshop gyro of the workshop model, "Sensors", :math:`\tilde\omega_k = \omega_k + n_k`,
:math:`n_k \sim \mathcal N(0, (p/\Delta t) I_3)`, and draws exactly the same
numbers (3 normals per step; with :math:`\sigma_u > 0` it draws 6 per step,
:math:`[N_{v,k}, N_{u,k}]`, in row order).
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.validation import InvalidParameterError, finite_number, finite_vector


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
    """

    def __init__(self, noise_power: float, dt: float, *, bias_random_walk: float = 0.0,
                 initial_bias_radps=(0.0, 0.0, 0.0), scale_misalignment=None):
        self.noise_power = finite_number("gyro_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.bias_random_walk = finite_number("gyro_bias_random_walk", bias_random_walk,
                                              minimum=0.0)
        self.initial_bias_radps = finite_vector("gyro_initial_bias_radps", initial_bias_radps, 3)
        self.scale_misalignment = scale_misalignment_matrix("gyro_scale_misalignment",
                                                            scale_misalignment)
        self.std_radps = self.reading_std(self.noise_power, self.dt, self.bias_random_walk)
        self.bias_step_std = self.bias_random_walk * math.sqrt(self.dt)

    @staticmethod
    def reading_std(noise_power: float, dt: float, bias_random_walk: float) -> float:
        """Per-sample white-noise σ, rad/s: ``√(σ_v²/Δt + σ_u²Δt/12)``; with
        ``σ_u = 0`` exactly the workshop's ``√(p/Δt)``."""
        return math.sqrt(noise_power / dt + bias_random_walk ** 2 * dt / 12.0)

    @property
    def normals_per_step(self) -> int:
        """Standard normals drawn per sample: 3, or 6 with a bias random walk."""
        return 6 if self.bias_random_walk > 0 else 3

    def measure(self, omega_true_radps: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(N, 3)`` in rad/s for true rates ``(N, 3)`` (see :meth:`measure_with_bias`)."""
        return self.measure_with_bias(omega_true_radps, rng)[0]

    def measure_with_bias(self, omega_true_radps: np.ndarray, rng: np.random.Generator
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Readings ``(N, 3)`` and the true bias ``β_k`` ``(N, 3)``, both rad/s.

        Draws ``N × normals_per_step`` standard normals from ``rng`` in row
        order, so the same generator state gives the same noise whatever else
        is simulated.
        """
        omega_true = np.asarray(omega_true_radps, dtype=float)
        if not self.has_bias_model:
            # The workshop gyro, exactly: ω + σ n.
            noise = rng.standard_normal(omega_true.shape)
            return omega_true + self.std_radps * noise, np.zeros_like(omega_true)
        normals = rng.standard_normal((len(omega_true), self.normals_per_step))
        rates = omega_true
        if self.scale_misalignment is not None:
            rates = rates + omega_true @ self.scale_misalignment.T
        # β_k for k = 0 … N (one more than the samples: the end of the last step).
        steps = (self.bias_step_std * normals[:, 3:] if self.bias_random_walk > 0
                 else np.zeros((len(omega_true), 3)))
        bias = self.initial_bias_radps + np.concatenate(
            [np.zeros((1, 3)), np.cumsum(steps, axis=0)], axis=0)
        rates = rates + 0.5 * (bias[:-1] + bias[1:])
        return rates + self.std_radps * normals[:, :3], bias[:-1]

    @property
    def has_bias_model(self) -> bool:
        """True unless this is the workshop gyro (no bias, no scale or misalignment)."""
        return (self.bias_random_walk > 0 or bool(np.any(self.initial_bias_radps))
                or self.scale_misalignment is not None)
