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
"""
from __future__ import annotations

import inspect
import math
import sys
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from dynamics.validation import (
    MAX_MEASURED_RATE_RADPS,
    InvalidParameterError,
    axis_standard_deviations,
    covariance_matrix,
    finite_number,
    finite_vector,
    nonzero_quaternion,
    one_of,
)
from estimators import sensing
from estimators.sampled_rate import SampledRate, derived_rate_interpolation
from estimators.tunable import (GATE_PROBABILITY, GYRO_BIAS_RANDOM_WALK, GYRO_NOISE,
                                MAGNETIC_NORM_TOLERANCE, MEASUREMENT_SCALE)

#: What an estimator does with a measurement that cannot be used (a
#: non-finite rate, a non-finite or zero reading).
ON_INVALID = ("raise", "skip")
#: Which estimate a filter's step returns: before or after that step's reading.
OUTPUTS = ("prior", "posterior")


class InvalidMeasurementError(InvalidParameterError):
    """A measurement an estimator cannot use; the message names the step,
    the value and the rule."""


class InvalidEstimateError(InvalidParameterError):
    """An estimator returned something that is not an attitude (a quaternion
    off the unit sphere, or not four numbers): a defect of that estimator."""


#: How far ``|q|²`` of an estimate may be from 1: far above the rounding of
#: a normalisation (1e-16), far below any quaternion a filter would output.
UNIT_NORM_TOLERANCE = 1e-6


class AttitudeEstimator:
    """Base class: subclasses implement :meth:`_step` and :meth:`reset`.

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

    @classmethod
    def derived_fields(cls, scenario) -> dict:
        """Values of this estimator's :attr:`owned_fields` (by scenario field
        name) that a scenario leaves unset, derived from its sensors (the
        scenario is complete but for these)."""
        return {}

    @classmethod
    def settings_from_scenario(cls, scenario) -> dict:
        """Constructor keywords taken from ``scenario`` before its
        ``[estimators.NAME]`` options (override to derive more, e.g. noise
        densities from the sensor models)."""
        settings = {"dt": scenario.dt}
        settings.update({keyword: getattr(scenario, field)
                         for keyword, field in cls.scenario_defaults.items()})
        return settings

    @classmethod
    def constructor_defaults(cls) -> dict:
        """The constructor's own defaults of its keyword-only settings."""
        return {name: parameter.default for name, parameter in
                inspect.signature(cls.__init__).parameters.items()
                if parameter.kind is inspect.Parameter.KEYWORD_ONLY
                and parameter.default is not inspect.Parameter.empty}

    @classmethod
    def configured_settings(cls, scenario) -> dict:
        """The constructor keywords ``scenario`` gives: its defaults for this
        estimator, then its ``[estimators.NAME]`` section."""
        settings = cls.settings_from_scenario(scenario)
        settings.update(cls.scenario_section(scenario))
        return settings

    @classmethod
    def from_scenario(cls, scenario, **overrides) -> "AttitudeEstimator":
        """This estimator as ``scenario`` configures it (``overrides`` last)."""
        settings = cls.configured_settings(scenario)
        settings.update(overrides)
        return cls(**settings)

    @classmethod
    def scenario_section(cls, scenario) -> dict:
        """This estimator's ``[estimators.NAME]`` section of ``scenario``: a
        registry class's under its :attr:`name`, a user's under its
        ``"package.module:ClassName"`` spec (so the Python API applies the
        same section the command line does)."""
        options = getattr(scenario, "estimator_options", {}) or {}
        # A registry name's section is the registry class's (and its subclasses'),
        # never a user's class that happens to share its name.
        section = dict(options.get(cls.name, {})) if _registry_class(cls) is not None else {}
        for key, values in options.items():
            module_name, colon, class_name = key.partition(":")
            module = sys.modules.get(module_name) if colon else None
            if module is not None and getattr(module, class_name, None) is cls:
                section.update(values)
        return section

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """The settings an ``[estimators.NAME]`` section may give: the
        constructor's keyword-only arguments but ``dt`` (the scenario's)."""
        return tuple(name for name, parameter in inspect.signature(cls.__init__).parameters.items()
                     if parameter.kind is inspect.Parameter.KEYWORD_ONLY and name != "dt")

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

    #: Whether :meth:`_step_at` applies a reading at its own time (a reading
    #: off the gyro grid); if not, such a reading is applied at its step.
    applies_reading_times = False

    def step(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray | None = None,
             offset_s: float = 0.0, vectors=()) -> np.ndarray:
        """Consume step ``k``'s measurements and return ``q̂[k]`` as a ``(4,)`` array.

        Measurements are checked here, where they enter: a rate that is not 3
        finite numbers, or a reading that is not 4 finite numbers of non-zero
        norm, or a rate beyond ±:data:`MAX_MEASURED_RATE_RADPS`, raises
        :class:`InvalidMeasurementError` naming the step and the value, or,
        with ``on_invalid="skip"``, is treated as missing (the last good rate
        is held; the reading is ignored) and counted in :attr:`skipped`.
        A step whose estimate or state is not finite (see
        :meth:`state_is_finite`) marks the estimator diverged: that step's
        estimate and every later one is NaN. Subclasses implement :meth:`_step`.

        Parameters
        ----------
        omega_meas_radps : (3,) array
            Gyro reading at step ``k``, rad/s, body frame.
        star_tracker_quat : (4,) array or None
            The star tracker's reading if one was taken at step ``k``
            (``available[k]``), else None.
        offset_s : float
            When the reading was taken, seconds after ``t_k`` (``0 <= τ < dt``;
            0 on the gyro grid). With ``τ > 0`` the estimate of ``t_k`` comes
            first, without the reading; the reading is applied at its own time
            by estimators that can (:attr:`applies_reading_times`:
            propagate to ``t_k + τ``, update, propagate on to ``t_{k+1}``).
        vectors : sequence of :class:`sensors.vector.VectorObservation`
            The vector readings taken at ``t_k`` (applied, in order, after the
            star tracker's, by estimators with :attr:`uses_vector_readings`;
            ignored by the others). One whose vectors are not 3 finite
            numbers (a zero reference) or whose variance is not > 0 is refused
            like a bad reading (or, with ``"skip"``, counted in ``skipped["vector"]``).
        """
        omega = self._checked_rate(omega_meas_radps)
        if star_tracker_quat is not None:
            star_tracker_quat = self._checked_reading(star_tracker_quat)
        if vectors:
            vectors = self._checked_vectors(vectors) if self.uses_vector_readings else ()
        self.step_index += 1
        if self.diverged_step is not None:
            return np.full(4, np.nan)
        self._count_offered(star_tracker_quat, vectors)
        try:
            if offset_s and star_tracker_quat is not None:
                offset = self._checked_offset(offset_s)
                estimate = (self._step_at(omega, star_tracker_quat, offset, vectors) if vectors
                            else self._step_at(omega, star_tracker_quat, offset))
            elif vectors:
                estimate = self._step(omega, star_tracker_quat, vectors)
            else:
                estimate = self._step(omega, star_tracker_quat)
        except np.linalg.LinAlgError:      # a covariance no longer positive definite
            estimate = None
        except ValueError:                 # scipy refusing a non-finite matrix
            if self.state_is_finite():
                raise
            estimate = None
        if estimate is None or not (finite_state(estimate) and self.state_is_finite()):
            self.diverged_step = self.step_index - 1
            return np.full(4, np.nan)
        return self._checked_estimate(estimate)

    def _checked_estimate(self, estimate) -> np.ndarray:
        """The step's estimate, if it is a unit quaternion: anything else is
        no attitude (the error metric would clip ``[10, 0, 0, 0]`` to a
        perfect 0°, and score a zero quaternion 180°), so it is refused,
        naming the class, the step and the value."""
        values = np.asarray(estimate, dtype=float).ravel().tolist()
        norm2 = math.fsum(v * v for v in values) if len(values) == 4 else math.nan
        if not abs(norm2 - 1.0) <= UNIT_NORM_TOLERANCE:
            raise InvalidEstimateError(
                f"{type(self).__name__}'s estimate at step {self.step_index - 1}", values,
                f"must be a unit quaternion (|q|^2 within {UNIT_NORM_TOLERANCE:g} of 1; "
                f"this one's is {norm2:.6g}): normalise it before returning it")
        return estimate

    def _count_offered(self, star_tracker_quat, vectors) -> None:
        """Count the step's readings of the sensors this estimator reads."""
        reads, offered = self.reads, self.offered
        if star_tracker_quat is not None and (reads is None or "star_tracker" in reads):
            offered["star_tracker"] = offered.get("star_tracker", 0) + 1
        for observation in vectors:
            sensor = observation.sensor
            if reads is None or sensor in reads:
                offered[sensor] = offered.get(sensor, 0) + 1

    def readings_used(self) -> int:
        """How many of the readings offered since the last reset it applied:
        those offered (:attr:`offered`) but those gating rejected
        (:attr:`rejected`). Zero with readings offered means its estimate
        was the gyro's alone (a static solver that never solved overrides it)."""
        return sum(self.offered.values()) - sum(self.rejected.values())

    def _checked_rate(self, omega_meas_radps) -> np.ndarray:
        """The step's rate, or the last good one under ``on_invalid="skip"``."""
        omega = _real_array("omega_meas_radps", omega_meas_radps, strict=False)
        if omega.shape != (3,) or not math.isfinite(omega[0] + omega[1] + omega[2]):
            return self._invalid("rate", "omega_meas_radps", omega_meas_radps,
                                 "must be 3 finite numbers (rad/s)", self._last_rate)
        if max(abs(omega[0]), abs(omega[1]), abs(omega[2])) > MAX_MEASURED_RATE_RADPS:
            return self._invalid("rate", "omega_meas_radps", omega_meas_radps,
                                 f"each component must be within ±{MAX_MEASURED_RATE_RADPS:g} "
                                 "rad/s (beyond any spacecraft or hand-held IMU)",
                                 self._last_rate)
        self._last_rate = omega
        return omega

    def _checked_vectors(self, vectors) -> tuple:
        """The step's usable vector readings (a bad one raises, or is skipped and counted)."""
        if hasattr(vectors, "body"):        # one reading, not a sequence of them
            raise InvalidMeasurementError(f"vectors at step {self.step_index}", vectors,
                                          "must be a sequence of VectorObservation (one "
                                          "reading goes in a list: [observation])")
        kept = []
        for observation in vectors:
            body = _real_array("vector body", getattr(observation, "body", None), strict=False)
            reference = _real_array("vector reference", getattr(observation, "reference", None),
                                    strict=False)
            variance = getattr(observation, "variance", math.nan)
            if isinstance(variance, (bool, np.bool_)) or \
                    not isinstance(variance, (int, float, np.integer, np.floating)):
                variance = math.nan         # text, None: no variance
            if (body.shape == (3,) and reference.shape == (3,)
                    and np.all(np.isfinite(body)) and np.all(np.isfinite(reference))
                    and reference @ reference > 0 and math.isfinite(variance) and variance > 0):
                kept.append(observation)
                continue
            self._invalid("vector", f"vector reading of {getattr(observation, 'sensor', '?')}",
                          observation, "must have 3 finite numbers in body and reference (a "
                          "non-zero reference) and a variance > 0", None)
        return tuple(kept)

    def _checked_offset(self, offset_s) -> float:
        """A reading's offset after its step's time: in ``[0, dt)``."""
        try:
            offset = float(offset_s)
        except (TypeError, ValueError):
            offset = math.nan
        if not 0.0 <= offset < self.dt:
            raise InvalidMeasurementError(f"offset_s at step {self.step_index - 1}", offset_s,
                                          f"must be in [0, dt = {self.dt:g}) seconds")
        return offset

    def _step_at(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
                 offset_s: float, vectors=()) -> np.ndarray:
        """A step whose reading was taken ``offset_s`` after ``t_k``. This
        base applies it at the step (an estimator without a notion of time
        within a step); :attr:`applies_reading_times` estimators override it."""
        if vectors:
            return self._step(omega_meas_radps, star_tracker_quat, vectors)
        return self._step(omega_meas_radps, star_tracker_quat)

    def _checked_reading(self, star_tracker_quat):
        """The step's reading, or None under ``on_invalid="skip"``."""
        reading = _real_array("star_tracker_quat", star_tracker_quat, strict=False)
        norm2 = reading @ reading if reading.shape == (4,) else math.nan
        if not (math.isfinite(norm2) and norm2 > 1e-24):
            return self._invalid("reading", "star_tracker_quat", star_tracker_quat,
                                 "must be 4 finite numbers of non-zero norm", None)
        return star_tracker_quat

    def state_is_finite(self) -> bool:
        """Whether the state the next step starts from is finite (checked
        after every step; a filter also checks its covariance, see
        :func:`finite_state`). Once it is not, the estimator has *diverged*:
        :attr:`diverged_step` records the step and every estimate from that
        step on is NaN, so a diverged run never scores as a number. The
        engine's kernels make the same test at the same step."""
        return True

    def _invalid(self, kind, name, value, rule, replacement):
        if self.on_invalid == "raise":
            raise InvalidMeasurementError(f"{name} at step {self.step_index}", value, rule)
        self.skipped[kind] += 1
        return replacement

    def _step(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray | None,
              vectors=()) -> np.ndarray:
        """The estimator's own step, on checked measurements (``vectors`` only
        given to an estimator with :attr:`uses_vector_readings`)."""
        raise NotImplementedError

    def run(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
            available: np.ndarray, offset_s: np.ndarray | None = None, *,
            vectors=None, progress=None) -> np.ndarray:
        """Reset, then step through a whole record; returns ``(N, 4)`` estimates.

        Parameters
        ----------
        omega_meas_radps : (N, 3) array, rad/s
        star_tracker_quat : (N, 4) array, the held star tracker output
        available : (N,) bool array, True where a new reading was taken
        offset_s : (N,) array, optional
            Seconds after ``t_k`` each step's reading was taken (off the gyro
            grid; see :meth:`step`); zeros if None.
        vectors : sequence of :class:`sensors.vector.VectorReadings`, optional
            Each vector sensor's readings over the record (``(N, 3)`` rows).
        progress : a progress bar (``update(n)``), optional
            Advanced by one per step (every :data:`PROGRESS_EVERY` steps).
        """
        omega, star, available, offsets = self._start_record(
            omega_meas_radps, star_tracker_quat, available, offset_s)
        vectors = checked_vector_record(vectors, len(omega))
        estimates = np.empty((len(omega), 4))
        with quiet_overflow():
            for k in range(len(omega)):
                estimates[k] = self.step(omega[k], star[k] if available[k] else None,
                                         offsets[k], observations_at(vectors, k))
                _advance(progress, k, len(omega))
        return estimates

    def _start_record(self, omega_meas_radps, star_tracker_quat, available, offset_s=None):
        """Reset, and check a whole record's shapes: ``(N, 3)`` rates, ``(N, 4)``
        readings, ``(N,)`` booleans and ``(N,)`` offsets, one row per step
        (values are checked step by step, in :meth:`step`)."""
        self.reset()
        self._restart_count()
        omega = _real_array("omega_meas_radps", omega_meas_radps)
        star = _real_array("star_tracker_quat", star_tracker_quat)
        flags = np.asarray(available)
        n = len(omega) if omega.ndim == 2 else -1
        offsets = (np.zeros(max(n, 0)) if offset_s is None
                   else _real_array("offset_s", offset_s))
        for name, array, shape in (("omega_meas_radps", omega, (n, 3)),
                                   ("star_tracker_quat", star, (n, 4)),
                                   ("available", flags, (n,)), ("offset_s", offsets, (n,))):
            if n < 0 or array.shape != shape:
                rule = (f"must have shape {shape}: one row per step, as the rates" if n >= 0
                        else "must have shape (N, 3): one row per step")
                raise InvalidMeasurementError(f"{name} of shape", array.shape, rule)
        if flags.dtype != bool:
            raise InvalidMeasurementError("available", flags, "must be booleans (True where "
                                          "a reading was taken)")
        return omega, star, flags, offsets

    def track(self, omega_meas_radps: np.ndarray, star_tracker_quat: np.ndarray,
              available: np.ndarray, offset_s: np.ndarray | None = None, *,
              vectors=None, progress=None) -> "EstimateTrace":
        """Like :meth:`run`, also collecting the covariance and bias estimate
        of every step (None where the estimator keeps none) and the steps of
        readings rejected by gating."""
        omega, star, available, offsets = self._start_record(
            omega_meas_radps, star_tracker_quat, available, offset_s)
        vectors = checked_vector_record(vectors, len(omega))
        n = len(omega)
        quat = np.empty((n, 4))
        columns = {"attitude_covariance": None, "bias_radps": None, "bias_covariance": None}
        nis, nis_dof = None, None
        with quiet_overflow():
            for k in range(n):
                skipped, rejections = self.skipped["reading"], len(self.rejections)
                quat[k] = self.step(omega[k], star[k] if available[k] else None, offsets[k],
                                    observations_at(vectors, k))
                used = (available[k] and self.skipped["reading"] == skipped
                        and ("star_tracker" not in (sensor for _, sensor in
                                                    self.rejections[rejections:])))
                innovation = self.innovation_nis if used and self.diverged_step is None else None
                if innovation is not None:
                    if nis is None:
                        nis, nis_dof = np.full(n, np.nan), self.innovation_dof
                    nis[k] = innovation
                self._collect(columns, k, n)
                if nis is not None and self.diverged_step is not None:
                    nis[k] = np.nan
                _advance(progress, k, n)
        rejected = {}
        for k, sensor in self.rejections:
            rejected.setdefault(sensor, []).append(k)
        return EstimateTrace(quat=quat, **columns, nis=nis, nis_dof=nis_dof,
                             rejected={sensor: np.array(steps) for sensor, steps in
                                       rejected.items()})

    def _collect(self, columns: dict, k: int, n: int) -> None:
        """Step ``k``'s covariance and bias estimate into ``columns`` (NaN once diverged)."""
        for key in columns:
            value = getattr(self, key)
            if value is None:
                continue
            if columns[key] is None:
                columns[key] = np.empty((n,) + np.shape(value))
            columns[key][k] = value if self.diverged_step is None else np.nan

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dt={self.dt!r})"


#: A record's progress bar is advanced this many steps at a time.
PROGRESS_EVERY = 1000


def _advance(progress, k: int, n: int) -> None:
    """Advance ``progress`` after step ``k`` of ``n`` (every
    :data:`PROGRESS_EVERY` steps and at the last; a bar's update costs
    microseconds, a step of a filter tens)."""
    if progress is not None and ((k + 1) % PROGRESS_EVERY == 0 or k + 1 == n):
        progress.update((k % PROGRESS_EVERY) + 1)


def _registry_class(cls):
    """The class of this package that gave ``cls`` its name — a registry
    estimator, ``cls`` itself or one it derives from — or None: a user's
    class that only shares a registry name. (Found by where the name was
    declared, not by importing the registry, which imports this module.)"""
    return next((klass for klass in cls.__mro__
                 if klass is not AttitudeEstimator and "name" in vars(klass)
                 and klass.name == cls.name
                 and klass.__module__.partition(".")[0] == __name__.partition(".")[0]), None)


def quiet_overflow():
    """No numpy warnings over a record: overflow on the way to divergence is
    what :meth:`AttitudeEstimator.step` detects and reports, once (entered per
    record, not per step: it costs about 1.5 µs)."""
    return np.errstate(over="ignore", invalid="ignore", divide="ignore")


def observations_at(vectors, k: int) -> tuple:
    """Step ``k``'s vector readings: each sensor's ``observation(k)`` where it
    is ``available`` (:class:`sensors.vector.VectorReadings`, duck-typed:
    estimators do not import sensors), or ()."""
    if not vectors:
        return ()
    return tuple(readings.observation(k) for readings in vectors if readings.available[k])


def checked_vector_record(vectors, n_steps: int) -> tuple:
    """A record's vector readings: each sensor's arrays one row per step."""
    if vectors is None:
        return ()
    if hasattr(vectors, "body"):            # one sensor's readings, not a sequence of them
        raise InvalidMeasurementError("vectors", type(vectors).__name__, "must be a sequence "
                                      "of VectorReadings, one per sensor (one sensor's go in "
                                      "a list: [readings])")
    vectors = tuple(vectors)
    for readings in vectors:
        for name, shape in (("body", (n_steps, 3)), ("reference", (n_steps, 3)),
                            ("available", (n_steps,)), ("variance", (n_steps,))):
            array = np.asarray(getattr(readings, name, None))
            if array.shape != shape:
                raise InvalidMeasurementError(f"vectors[{getattr(readings, 'sensor', '?')}]."
                                              f"{name} of shape", array.shape,
                                              f"must have shape {shape}: one row per step")
    return vectors


def _real_array(name: str, value, strict: bool = True) -> np.ndarray:
    """``value`` as a float array. Complex, boolean, string or object data are
    refused (numpy would drop an imaginary part, or fail deep inside a
    filter); with ``strict=False`` they come back as an empty array, which
    the caller's shape check then refuses with its own rule."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):      # ragged lists
        array = np.asarray(None)
    if array.dtype.kind in "iuf":
        return array.astype(float, copy=False)
    if not strict:
        return np.empty(0)
    raise InvalidMeasurementError(name, value, "must be real numbers (not complex, booleans "
                                  "or text)")


@lru_cache(maxsize=64)
def gate_threshold(probability: float, dof: int) -> float:
    """The χ² quantile a reading's NIS must not exceed to pass the gate."""
    from scipy.stats import chi2
    return float(chi2.ppf(probability, dof))


def gate_probability_setting(value) -> float | None:
    """A gating probability: None (off) or within (0, 1)."""
    if value is None:
        return None
    probability = finite_number("gate_probability", value)
    if not 0.0 < probability < 1.0:
        raise InvalidParameterError("gate_probability", value, "must be within 0 and 1 "
                                    "(e.g. 0.9999), or None for no gating")
    return probability


def norm_tolerance_setting(value) -> float | None:
    """A magnetic norm tolerance: None (off) or a fraction > 0."""
    if value is None:
        return None
    return finite_number("magnetic_norm_tolerance", value, strictly_positive=True)


def finite_state(vector, covariance=None) -> bool:
    """The divergence test: ``sum(vector)`` and ``trace(covariance)`` finite
    (a NaN or infinity in either makes its sum non-finite). Summed left to
    right in Python floats, as the engine's kernels sum them, and ten times
    faster than numpy's calls on a few numbers: it runs after every step."""
    if not math.isfinite(sum(np.asarray(vector).tolist())):
        return False
    return covariance is None or math.isfinite(sum(np.diagonal(covariance).tolist()))


def axis_sigmas(name: str, value) -> np.ndarray:
    """One standard deviation per axis (a number means the same on all three),
    >= 0 and small enough that its square (a variance) is finite."""
    return axis_standard_deviations(name, value)


class KalmanEstimator(AttitudeEstimator):
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
    :meth:`_without_reading`.
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
    #: The χ² probability of innovation gating, or None (off; see :meth:`accepts`).
    gate_probability = None

    def correct_vector(self, observation) -> None:
        """The update with one vector reading (:class:`sensors.vector.VectorObservation`)."""
        raise NotImplementedError

    #: Magnetic disturbance detection: a magnetometer reading whose
    #: magnitude is off its reference's by more than this fraction is
    #: rejected before any update (None: no test). See :meth:`passes_norm`.
    magnetic_norm_tolerance = None

    def passes_norm(self, observation) -> bool:
        r"""Whether a vector reading passes the magnetic disturbance test,
        :math:`\bigl|\,\lVert b\rVert / \lVert r\rVert - 1\bigr| \le`
        :attr:`magnetic_norm_tolerance` (magnetometers only; always, when it
        is None). A disturbed field (a magnet, steel nearby) changes its
        magnitude; its direction alone can pass the χ² gate while it pulls
        the heading away (VQF's detector tests the magnitude and the dip;
        Laidig & Seel 2023, §3.3). Rejected readings are counted as the
        gate counts them."""
        tolerance = self.magnetic_norm_tolerance
        if tolerance is None or observation.sensor != "magnetometer":
            return True
        b0, b1, b2 = np.asarray(observation.body, dtype=float).tolist()
        r0, r1, r2 = np.asarray(observation.reference, dtype=float).tolist()
        ratio = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2) / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if abs(ratio - 1.0) <= tolerance:
            return True
        self._reject(observation.sensor)
        return False

    def _reject(self, sensor: str) -> None:
        """Count a rejected reading of ``sensor`` at this step."""
        self.rejected[sensor] = self.rejected.get(sensor, 0) + 1
        self.rejections.append((self.step_index - 1, sensor))

    def accepts(self, y: np.ndarray, S: np.ndarray, dof: int, sensor: str) -> bool:
        r"""Innovation gating: whether a reading of innovation ``y`` and
        innovation covariance ``S`` passes the χ² test of its NIS,
        :math:`y^\mathsf{T} S^{-1} y \le \chi^2_{\text{dof}}(p)` with ``p`` the
        :attr:`gate_probability` (always, when it is None). A rejected reading
        is counted in :attr:`rejected` and is not applied: spacecraft reject
        albedo and glints this way, ground IMUs magnetic disturbances and
        linear acceleration."""
        if self.gate_probability is None:
            return True
        nis = float(y @ np.linalg.solve(S, y))
        if nis <= gate_threshold(self.gate_probability, dof):
            return True
        self._reject(sensor)
        return False

    #: The star tracker update's (y, S) on a step whose vector updates followed it.
    _tracker_innovation = None
    #: Set True before a run to sum each applied update's innovation terms
    #: in :attr:`innovation_sums` (the tuner's likelihood objective).
    log_innovations = False

    def _restart_count(self) -> None:
        super()._restart_count()
        #: With :attr:`log_innovations`: the updates applied since the run
        #: began (star tracker and vector readings alike), the sum of their
        #: NIS yᵀ S⁻¹ y and of their ln det S. The innovations' negative
        #: log-likelihood is half the two sums plus a constant.
        self.innovation_sums = {"updates": 0, "nis": 0.0, "log_det": 0.0}

    def _log_innovation(self, rejections: int) -> None:
        """Fold the update just made into :attr:`innovation_sums`, unless
        gating rejected it (``rejections``: their count before it)."""
        if len(self.rejections) != rejections:
            return
        kept = getattr(self, "filter", self)
        y, S = np.ravel(kept.y), np.atleast_2d(kept.S)
        sign, log_det = np.linalg.slogdet(S)
        sums = self.innovation_sums
        sums["updates"] += 1
        sums["nis"] += float(y @ np.linalg.solve(S, y)) if sign > 0 else math.inf
        sums["log_det"] += float(log_det) if sign > 0 else math.inf

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
                   output, rate_interpolation="hold") -> None:
        """Validate and keep the settings the six-state filters share."""
        self._set_rate_interpolation(rate_interpolation)
        self.gyro_noise = finite_number("gyro_noise", gyro_noise, minimum=0.0)
        self.gyro_bias_random_walk = finite_number("gyro_bias_random_walk",
                                                   gyro_bias_random_walk, minimum=0.0)
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


@dataclass(frozen=True)
class EstimateTrace:
    """An estimator's outputs over a record of ``N`` steps.

    Attributes
    ----------
    quat : (N, 4) estimates, scalar-first
    attitude_covariance : (N, 3, 3) rad², or None
    bias_radps : (N, 3) rad/s, or None
    bias_covariance : (N, 3, 3) (rad/s)², or None
    nis : (N,) the normalised innovation squared at reading steps (NaN
        elsewhere), or None
    nis_dof : its degrees of freedom, or None
    rejected : sensor name → steps of readings rejected by gating
    """

    quat: np.ndarray
    attitude_covariance: np.ndarray | None = None
    bias_radps: np.ndarray | None = None
    bias_covariance: np.ndarray | None = None
    nis: np.ndarray | None = None
    nis_dof: int | None = None
    #: sensor → the steps whose reading innovation gating rejected (empty without gating).
    rejected: dict = field(default_factory=dict)
