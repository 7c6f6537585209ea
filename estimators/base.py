"""The one interface every attitude estimator shares.

An estimator is fed, once per gyro step ``k``, the measured body rate and,
when the star tracker took a reading at that step, the reading; it answers
with its attitude estimate ``q̂[k]`` (scalar-first, unit norm). Swapping one
estimator for another is one line::

    estimator = DeadReckoning(dt=0.01)          # or QuaternionEKF(dt=0.01)
    q_est = estimator.run(omega_meas_radps, star_quat, available)

All arrays in and out are 1-D per step (``(3,)`` rates, ``(4,)``
quaternions) or stacked ``(N, ...)`` for whole runs.

Every estimator answers the same questions about the estimate :meth:`step`
last returned: :attr:`attitude` ``(4,)``, :attr:`attitude_covariance`
``(3, 3)`` in rad² of the body-frame small-angle error ``δθ`` with
``q_true = q̂ ⊗ δq(δθ)`` (None if it keeps none), :attr:`bias_radps` and
:attr:`bias_covariance` (None if it estimates no gyro bias). :meth:`track`
collects them over a whole record.

Estimators build themselves from a scenario with :meth:`from_scenario`: the
scenario supplies the defaults (:attr:`scenario_defaults`), its
``[estimators.NAME]`` section (``scenario.estimator_options[NAME]``) overrides
them. The scenario is duck-typed: this package never imports ``benchmarks``.

The interface is put together from one module per concern, each readable
alone: :mod:`estimators.settings` (the settings and their derivation from a
scenario), :mod:`estimators.readings` (the measurements, checked where they
enter), :mod:`estimators.stepping` (the step template and divergence),
:mod:`estimators.records` (runs over a whole record, and their traces) and,
for the filters, :mod:`estimators.gating` (innovation gating and its log).
This module joins them into :class:`AttitudeEstimator` and holds the bases
of the filters, :class:`KalmanEstimator` and :class:`AttitudeAndBiasEstimator`;
every name the project imports from it is still here.
"""
from __future__ import annotations

import inspect
import math

import numpy as np

from dynamics.validation import (covariance_matrix, finite_number, finite_vector,
                                 nonzero_quaternion, one_of)
from estimators import sensing
from estimators.gating import (InnovationGate, gate_probability_setting, gate_threshold,
                               norm_tolerance_setting)
from estimators.readings import (InvalidMeasurementError, MeasurementChecks,
                                 checked_vector_record, observations_at)
from estimators.records import PROGRESS_EVERY, EstimateTrace, RecordRuns, quiet_overflow
from estimators.sampled_rate import SampledRate, derived_rate_interpolation
from estimators.settings import ON_INVALID, OUTPUTS, SettingsFromScenario, axis_sigmas
from estimators.stepping import (UNIT_NORM_TOLERANCE, InvalidEstimateError, StepTemplate,
                                 finite_state)
from estimators.tunable import (GATE_PROBABILITY, GYRO_BIAS_RANDOM_WALK, GYRO_NOISE,
                                MAGNETIC_NORM_TOLERANCE, MEASUREMENT_SCALE)

#: The names other modules import from here, wherever each is defined.
__all__ = [
    "AttitudeEstimator", "KalmanEstimator", "AttitudeAndBiasEstimator", "EstimateTrace",
    "InvalidMeasurementError", "InvalidEstimateError", "ON_INVALID", "OUTPUTS",
    "UNIT_NORM_TOLERANCE", "PROGRESS_EVERY", "axis_sigmas", "finite_state",
    "gate_threshold", "gate_probability_setting", "norm_tolerance_setting",
    "checked_vector_record", "observations_at", "quiet_overflow",
]


class AttitudeEstimator(SettingsFromScenario, MeasurementChecks, StepTemplate, RecordRuns):
    """Base class: subclasses implement :meth:`_step` and :meth:`reset`.

    Its settings, measurement checks, step and runs over a record come from
    the mixins of :mod:`estimators.settings`, :mod:`estimators.readings`,
    :mod:`estimators.stepping` and :mod:`estimators.records`; here are what
    a class declares about itself, the per-run counts, and the questions
    every estimator answers about its last estimate.

    Attributes
    ----------
    name : str
        Short identifier used on the command line (``"ekf"``).
    label : str
        Human-readable name used in figure legends.
    dt : float
        Step in seconds between gyro samples.
    """

    name = "estimator"
    label = "Estimator"
    #: "online" (each estimate from the readings up to its step) or
    #: "offline" (from the whole record: a smoother), as tables say.
    mode = "online"
    #: Constructor keyword → the scenario attribute its default comes from.
    scenario_defaults = {"initial_attitude": "initial_state"}
    #: Keywords of :attr:`scenario_defaults` whose scenario field belongs to
    #: this estimator alone: ``[estimators.NAME]`` sets that field itself (so
    #: campaigns that vary it per run, such as the EKF's ``pc_exponent``, see it).
    owned_fields: tuple = ()
    #: Whether :meth:`step` applies vector readings (magnetometer, sun
    #: sensors, accelerometer: :class:`sensors.vector.VectorObservation`):
    #: True for the filters and the static solvers, False for dead reckoning;
    #: None (undeclared, as a user's class is until it says) means it does
    #: not, and :func:`benchmarks.simulation.simulate` warns that it ignores them.
    uses_vector_readings: bool | None = None
    #: The sensors whose readings it applies, besides the gyro
    #: (:mod:`estimators.sensing`'s names); None: undeclared (a user's class
    #: that does not say is never refused for its sensors).
    reads: frozenset | None = None
    #: Sets of sensors any one of which gives it an attitude reference; it is
    #: refused on data with none of them ((): the gyro suffices).
    needs: tuple = ()
    #: Whether its output has a heading reference at all (VQF 6D's has not:
    #: it is scored on its inclination, :func:`estimators.sensing.heading_observed`).
    has_heading: bool = True
    #: The settings a tuner may vary (:class:`estimators.tunable.Tunable`, one
    #: per constructor keyword): none for an estimator without noise settings.
    tunable: tuple = ()

    def __init__(self, *, dt: float, initial_attitude, on_invalid: str = "raise"):
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.initial_attitude = nonzero_quaternion("initial_state", initial_attitude)
        self.on_invalid = one_of("on_invalid", on_invalid, ON_INVALID)
        self._restart_count()

    def _restart_count(self) -> None:
        #: Steps taken since construction or the last run/track.
        self.step_index = 0
        #: Measurements skipped under ``on_invalid="skip"``: rates and readings.
        self.skipped = {"rate": 0, "reading": 0, "vector": 0}
        #: Readings rejected by innovation gating, by sensor (filters with a
        #: ``gate_probability``), and the ``(step, sensor)`` of each.
        self.rejected = {}
        self.rejections = []
        #: Readings offered to it, by sensor (those it :attr:`reads`): with
        #: :attr:`rejected`, what :meth:`readings_used` counts.
        self.offered = {}
        self._last_rate = np.zeros(3)
        #: The step where the estimate or its covariance stopped being finite
        #: (see :meth:`step`), or None.
        self.diverged_step = None

    def reset(self) -> None:
        """Return to the initial estimate, forgetting all measurements."""
        raise NotImplementedError

    @property
    def attitude_covariance(self) -> np.ndarray | None:
        """``(3, 3)`` rad²: covariance of the body-frame error of the last
        estimate, or None for an estimator that keeps no covariance."""
        return None

    @property
    def bias_radps(self) -> np.ndarray | None:
        """``(3,)`` rad/s: the gyro bias estimate, or None if not estimated."""
        return None

    @property
    def bias_covariance(self) -> np.ndarray | None:
        """``(3, 3)`` (rad/s)²: covariance of the bias estimate, or None."""
        return None

    @property
    def innovation_nis(self) -> float | None:
        """The normalised innovation squared ``yᵀ S⁻¹ y`` of the last
        star-tracker update, or None. Filters built on filterpy keep ``y``
        and ``S`` after each update (on their ``filter``, or on themselves);
        others return None."""
        kept = getattr(self, "filter", self)
        y, S = getattr(kept, "y", None), getattr(kept, "S", None)
        if getattr(self, "_tracker_innovation", None) is not None:
            y, S = self._tracker_innovation      # vector updates came after it
        if y is None or S is None or np.ndim(S) != 2:
            return None
        y = np.ravel(y)
        return float(y @ np.linalg.solve(S, y))

    @property
    def innovation_dof(self) -> int:
        """Degrees of freedom of :attr:`innovation_nis` (the reading's dimension)."""
        if getattr(self, "_tracker_innovation", None) is not None:
            return int(np.size(self._tracker_innovation[0]))
        return int(np.size(getattr(getattr(self, "filter", self), "y", ())))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dt={self.dt!r})"


class KalmanEstimator(InnovationGate, AttitudeEstimator):
    """An estimator around a filterpy filter, held as :attr:`filter`
    (composition, not inheritance: filterpy's ``batch_filter`` or
    ``rts_smoother`` would run on an error state without its reset and return
    meaningless numbers). After a step, ``filter`` is the place to inspect
    what filterpy keeps: ``x_prior``, ``P_prior``, ``x_post``, ``P_post``,
    ``y``, ``S``, ``K``. This base owns what the EKF, the MEKF and USQUE share:
    the step's template (output the prior, or correct and output the
    posterior; then propagate) and filterpy's bookkeeping of a reset.

    Subclasses set ``filter`` and ``output`` (``"prior"`` or ``"posterior"``)
    and implement :meth:`correct`, :meth:`propagate` and :meth:`_record`
    (keep ``_output``, whose first entry is the estimate); they may override
    :meth:`_without_reading`. Innovation gating, the magnetic disturbance
    test and the innovation log are :class:`~estimators.gating.InnovationGate`'s.
    """

    #: The filterpy filter: inspect ``x_prior``, ``P_post``, ``y``, ``S``, ``K`` there.
    filter: object

    def __init_subclass__(cls, **kwargs):
        """A subclass applies readings at their own times only if its
        ``propagate`` takes the part of a step (``dt``); one written to
        ``propagate(omega)`` applies them at their steps (and is told so)."""
        super().__init_subclass__(**kwargs)
        if "applies_reading_times" not in cls.__dict__:
            cls.applies_reading_times = "dt" in inspect.signature(cls.propagate).parameters
    output: str
    _output: tuple

    def correct(self, star_tracker_quat: np.ndarray) -> None:
        """The update with one reading (and, for an error-state filter, its reset)."""
        raise NotImplementedError

    def propagate(self, omega_meas_radps: np.ndarray, dt: float | None = None) -> None:
        """The prediction from step ``k`` to ``k + 1`` with the gyro's rate
        (over ``dt`` seconds if given: part of a step, see :meth:`_step_at`)."""
        raise NotImplementedError

    def _record(self) -> None:
        """Keep the estimate being output (``_output``)."""
        raise NotImplementedError

    def _without_reading(self) -> None:
        """What a step without a reading does in place of :meth:`correct`."""

    def _reset_filter(self, x: np.ndarray, P: np.ndarray) -> None:
        """filterpy's state, covariance and their prior and posterior copies."""
        f = self.filter
        f.x, f.P = x, P
        f.x_prior, f.P_prior = x.copy(), P.copy()
        f.x_post, f.P_post = x.copy(), P.copy()

    #: The filters apply vector readings: one sequential update per vector
    #: (:meth:`correct_vector`), after the star tracker's; any one attitude
    #: sensor gives them a reference.
    uses_vector_readings = True
    reads = frozenset(sensing.ATTITUDE_SENSORS)
    needs = sensing.ANY_ATTITUDE_SENSOR

    def correct_vector(self, observation) -> None:
        """The update with one vector reading (:class:`sensors.vector.VectorObservation`)."""
        raise NotImplementedError

    def _correct_logged(self, star_tracker_quat) -> None:
        """:meth:`correct`, its innovation logged if asked."""
        rejections = len(self.rejections)
        self.correct(star_tracker_quat)
        if self.log_innovations:
            self._log_innovation(rejections)

    def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()) -> np.ndarray:
        self._tracker_innovation = None
        estimate = self._estimate_at_step(star_tracker_quat, vectors)
        self.propagate(omega_meas_radps)
        return estimate

    def _estimate_at_step(self, star_tracker_quat, vectors=()) -> np.ndarray:
        """Output the prior, or correct (with the step's readings, if any) and
        output the posterior."""
        if self.output == "prior":
            self._record()
        if star_tracker_quat is not None:
            self._correct_logged(star_tracker_quat)
            if vectors:
                kept = getattr(self, "filter", self)
                self._tracker_innovation = (np.copy(getattr(kept, "y", None)),
                                            np.copy(getattr(kept, "S", None)))
        elif not vectors:
            self._without_reading()
        for observation in vectors:
            rejections = len(self.rejections)
            self.correct_vector(observation)
            if self.log_innovations:
                self._log_innovation(rejections)
        if self.output == "posterior":
            self._record()
        return self._output[0].copy()

    applies_reading_times = True

    def _step_at(self, omega_meas_radps, star_tracker_quat, offset_s: float,
                 vectors=()) -> np.ndarray:
        """A reading taken ``τ = offset_s`` after ``t_k`` (a tracker on its own
        clock): the estimate of ``t_k`` is output without it (prior and
        posterior are one there); then the filter propagates to ``t_k + τ``
        with the step's rate, updates, and propagates the rest of the step,
        ``Δt − τ`` (the continuous–discrete filter of M&C 2014, §6.2: each
        measurement is processed at its own time)."""
        if not self.applies_reading_times:
            return self._step(omega_meas_radps, star_tracker_quat, vectors)
        self._tracker_innovation = None
        estimate = self._estimate_at_step(None, vectors)
        self.propagate(omega_meas_radps, offset_s)
        self._correct_logged(star_tracker_quat)
        self.propagate(omega_meas_radps, self.dt - offset_s)
        return estimate


class AttitudeAndBiasEstimator(SampledRate, KalmanEstimator):
    """Base of the six-state filters (attitude error and gyro bias, e.g. the
    MEKF and USQUE): at each output they keep ``_output = (q̂, β̂, P)`` with
    ``P`` 6x6, its attitude block first, and answer the interface from it.
    They propagate with the rate held over each step or with the
    trapezoidal rule (``rate_interpolation``, :mod:`estimators.sampled_rate`)."""

    _output: tuple
    #: Both take the gyro's noise model and the star tracker's body-frame
    #: covariance from the scenario: filters matched to their sensors (a
    #: Gauss–Markov bias as its equivalent random walk).
    scenario_defaults = {"initial_attitude": "initial_state", "gyro_noise": "gyro_noise",
                         "gyro_bias_random_walk": "gyro_filter_bias_random_walk",
                         "measurement_covariance": "star_tracker_attitude_covariance_rad2"}
    #: The gyro's σ_v² and σ_u the filter assumes, a factor on the tracker's
    #: R, and the gate (tuned only when named: it is off by default).
    tunable = (GYRO_NOISE, GYRO_BIAS_RANDOM_WALK, MEASUREMENT_SCALE, GATE_PROBABILITY,
               MAGNETIC_NORM_TOLERANCE)

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """The scenario's settings; with a Gauss–Markov bias of σ_b, a bias
        prior of at least σ_b (``√(σ₀² + σ_b²)`` with σ₀ the default): the
        true bias starts as a draw of that spread. The prior also covers the
        gyro's declared initial bias: at least ``|b₀|`` on each axis (the
        filter starts its estimate at zero, so ``b₀`` is its initial error,
        and a prior narrower than it is overconfident from the start)."""
        settings = super().settings_from_scenario(scenario)
        sigma = inspect.signature(cls.__init__).parameters["initial_bias_sigma_radps"].default
        sigma_b = getattr(scenario, "gyro_bias_instability_radps", 0.0)
        if sigma_b > 0:
            sigma = math.hypot(sigma, sigma_b)
        declared = np.abs(np.asarray(getattr(scenario, "gyro_initial_bias_radps", np.zeros(3)),
                                     dtype=float))
        if np.any(declared > sigma):
            settings["initial_bias_sigma_radps"] = np.maximum(declared, sigma)
        elif sigma_b > 0:
            settings["initial_bias_sigma_radps"] = sigma
        settings["rate_interpolation"] = derived_rate_interpolation(scenario)
        return settings

    def _configure(self, *, gyro_noise, gyro_bias_random_walk, measurement_covariance,
                   initial_bias_radps, initial_attitude_sigma_rad, initial_bias_sigma_radps,
                   output, rate_interpolation="hold", gyro_scale_density=0.0) -> None:
        """Validate and keep the settings the six-state filters share."""
        self._set_rate_interpolation(rate_interpolation)
        self.gyro_noise = finite_number("gyro_noise", gyro_noise, minimum=0.0)
        self.gyro_bias_random_walk = finite_number("gyro_bias_random_walk",
                                                   gyro_bias_random_walk, minimum=0.0)
        self.gyro_scale_density = finite_number("gyro_scale_density", gyro_scale_density,
                                                minimum=0.0)
        self.R = covariance_matrix("measurement_covariance", measurement_covariance, size=3)
        self.initial_bias_radps = finite_vector("initial_bias_radps", initial_bias_radps, 3)
        attitude_sigma = axis_sigmas("initial_attitude_sigma_rad", initial_attitude_sigma_rad)
        bias_sigma = axis_sigmas("initial_bias_sigma_radps", initial_bias_sigma_radps)
        self.initial_covariance = np.diag(np.concatenate([attitude_sigma, bias_sigma]) ** 2)
        self.output = one_of("output", output, OUTPUTS)

    @property
    def attitude(self) -> np.ndarray:
        return self._output[0].copy()

    @property
    def bias_radps(self) -> np.ndarray:
        return self._output[1].copy()

    @property
    def attitude_covariance(self) -> np.ndarray:
        return self._output[2][:3, :3].copy()

    @property
    def bias_covariance(self) -> np.ndarray:
        return self._output[2][3:6, 3:6].copy()
