"""The workshop scenario: every setting of a run, validated where it enters.

:class:`Scenario` holds SPEC's defaults ("Default parameters"). A scenario
can be loaded from a TOML file whose keys are the field names (any subset;
unknown keys are an error) and then overridden field by field::

    scenario = Scenario.from_toml("scenarios/default.toml").replace(gyro_noise=1e-4)

Every value is checked on construction; a bad one raises
:class:`~dynamics.validation.InvalidParameterError` (a ``ValueError``) whose
message names the parameter, the value and the rule.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dynamics.validation import (
    InvalidParameterError,
    finite_number,
    finite_vector,
    inertia_tensor,
    nonzero_quaternion,
)
from estimators.ekf import covariance_matrix
from sensors.star_tracker import steps_between_readings


def _diag(*values):
    return field(default_factory=lambda: np.diag(values).astype(float))


def _vector(*values):
    return field(default_factory=lambda: np.array(values, dtype=float))


@dataclass(frozen=True, eq=False)
class Scenario:
    """All settings of one workshop run (SI units, radians).

    Attributes
    ----------
    tstop : float
        Simulated time, seconds (50).
    dt : float
        Gyro and estimator step, seconds (0.01, i.e. 100 Hz).
    inertia_tensor_kg_m2 : (3, 3) array
        Body inertia, kg m² (diag(1, 2, 3)); 3 numbers mean a diagonal.
    initial_attitude_quat : (4,) array
        True attitude at t = 0, scalar-first ([1, 0, 0, 0]).
    initial_rate_radps : (3,) array
        True body rate at t = 0, rad/s ([0.05, 0.05, 0]).
    gyro_noise : float
        Gyro noise power, rad²/s (1e-5).
    star_tracker_noise : float
        Star tracker noise power per quaternion component (1e-6).
    time_between_measurements : float
        Seconds between star tracker readings; a whole multiple of dt (0.2).
    pc_exponent : float
        EKF process covariance Q = exp(pc_exponent) I₄ (-8.7).
    measurement_covariance : (4, 4) array
        EKF measurement covariance R (I₄); a number means that times I₄.
    initial_state : (4,) array
        Initial estimate of every estimator ([1, 0, 0, 0]).
    initial_covariance : float
        EKF P₀ = initial_covariance · I₄ (1e-12).
    """

    tstop: float = 50.0
    dt: float = 0.01
    inertia_tensor_kg_m2: np.ndarray = _diag(1.0, 2.0, 3.0)
    initial_attitude_quat: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    initial_rate_radps: np.ndarray = _vector(0.05, 0.05, 0.0)
    gyro_noise: float = 1e-5
    star_tracker_noise: float = 1e-6
    time_between_measurements: float = 0.2
    pc_exponent: float = -8.7
    measurement_covariance: np.ndarray = field(default_factory=lambda: np.eye(4))
    initial_state: np.ndarray = _vector(1.0, 0.0, 0.0, 0.0)
    initial_covariance: float = 1e-12

    def __post_init__(self):
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        set_("dt", finite_number("dt", self.dt, strictly_positive=True))
        set_("tstop", finite_number("tstop", self.tstop, strictly_positive=True))
        if self.tstop < self.dt:
            raise InvalidParameterError("tstop", self.tstop, f"must be >= dt = {self.dt:g}")
        set_("inertia_tensor_kg_m2", inertia_tensor("inertia_tensor_kg_m2",
                                                    self.inertia_tensor_kg_m2))
        set_("initial_attitude_quat", nonzero_quaternion("initial_attitude_quat",
                                                         self.initial_attitude_quat))
        set_("initial_rate_radps", finite_vector("initial_rate_radps", self.initial_rate_radps, 3))
        set_("gyro_noise", finite_number("gyro_noise", self.gyro_noise, minimum=0.0))
        set_("star_tracker_noise", finite_number("star_tracker_noise", self.star_tracker_noise,
                                                 minimum=0.0))
        set_("time_between_measurements", finite_number(
            "time_between_measurements", self.time_between_measurements, strictly_positive=True))
        steps_between_readings(self.time_between_measurements, self.dt)
        set_("pc_exponent", finite_number("pc_exponent", self.pc_exponent))
        if math.exp(self.pc_exponent) == 0.0:
            raise InvalidParameterError("pc_exponent", self.pc_exponent,
                                        "must be > -745 so that exp(pc_exponent) > 0")
        set_("measurement_covariance", covariance_matrix("measurement_covariance",
                                                         self.measurement_covariance))
        set_("initial_state", nonzero_quaternion("initial_state", self.initial_state))
        set_("initial_covariance", finite_number("initial_covariance", self.initial_covariance,
                                                 strictly_positive=True))

    @property
    def n_steps(self) -> int:
        """``N = round(tstop / dt) + 1`` samples, ``t_k = k dt``."""
        return round(self.tstop / self.dt) + 1

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.n_steps) * self.dt

    def replace(self, **changes) -> "Scenario":
        """A copy with some fields changed (validated like the original)."""
        unknown = set(changes) - set(field_names())
        if unknown:
            name = sorted(unknown)[0]
            raise InvalidParameterError(name, changes[name], "is not a scenario setting; "
                                        f"known: {', '.join(field_names())}")
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """Plain-Python values (lists for arrays), e.g. for JSON or TOML."""
        return {name: (value.tolist() if isinstance(value, np.ndarray) else value)
                for name, value in ((f, getattr(self, f)) for f in field_names())}

    @classmethod
    def from_toml(cls, path) -> "Scenario":
        """Load a scenario file; keys are field names, missing ones take defaults."""
        path = Path(path)
        try:
            with path.open("rb") as handle:
                data = tomllib.load(handle)
        except FileNotFoundError:
            raise InvalidParameterError("scenario", str(path), "file does not exist") from None
        except OSError as err:
            raise InvalidParameterError("scenario", str(path),
                                        f"cannot be read ({err.strerror})") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise InvalidParameterError("scenario", str(path),
                                        f"must be valid TOML ({err})") from None
        return cls().replace(**data)


def field_names() -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(Scenario))
