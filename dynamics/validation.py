"""Checks applied where values enter the toolkit (files, flags, constructors).

Every failure raises :class:`InvalidParameterError`, a ``ValueError`` whose
one-line message names the parameter, the value it was given, and the rule it
broke, e.g. ``gyro_noise = -1.0: must be a finite number >= 0``.
"""
from __future__ import annotations

import math

import numpy as np


class InvalidParameterError(ValueError):
    """A parameter broke a rule; ``str(err)`` is a one-line explanation."""

    def __init__(self, name: str, value, rule: str):
        self.name = name
        self.value = value
        self.rule = rule
        super().__init__(f"{name} = {_show(value)}: {rule}")


def _show(value) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def finite_number(name: str, value, *, minimum: float | None = None,
                  strictly_positive: bool = False) -> float:
    """Return ``value`` as a float, or raise if it is not a finite real number
    within the bound."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidParameterError(name, value, "must be a number")
    number = float(value)
    if not math.isfinite(number):
        raise InvalidParameterError(name, value, "must be finite")
    if strictly_positive and number <= 0:
        raise InvalidParameterError(name, value, "must be > 0")
    if minimum is not None and number < minimum:
        raise InvalidParameterError(name, value, f"must be >= {minimum:g}")
    return number


def finite_vector(name: str, value, length: int) -> np.ndarray:
    """Return ``value`` as a float array of shape ``(length,)``."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, f"must be a list of {length} numbers") from None
    if array.shape != (length,):
        raise InvalidParameterError(name, value, f"must be a list of {length} numbers")
    if not np.all(np.isfinite(array)):
        raise InvalidParameterError(name, value, "must be finite")
    return array


def nonzero_quaternion(name: str, value) -> np.ndarray:
    """Return ``value`` normalised to a unit quaternion; reject a zero one."""
    q = finite_vector(name, value, 4)
    norm = float(np.linalg.norm(q))
    if norm < 1e-12:
        raise InvalidParameterError(name, value, "must be a non-zero quaternion [w, x, y, z]")
    return q / norm


def inertia_tensor(name: str, value) -> np.ndarray:
    """Return a physically valid inertia tensor (kg m^2) as a 3x3 array.

    Accepts a 3x3 matrix or the 3 principal moments of a diagonal tensor. The
    tensor must be symmetric positive definite and its principal moments must
    satisfy the triangle inequality ``I_a <= I_b + I_c`` that every real mass
    distribution obeys.
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, "must be a 3x3 matrix or 3 principal moments") from None
    if array.shape == (3,):
        array = np.diag(array)
    if array.shape != (3, 3):
        raise InvalidParameterError(name, value, "must be a 3x3 matrix or 3 principal moments")
    if not np.all(np.isfinite(array)):
        raise InvalidParameterError(name, value, "must be finite")
    if not np.allclose(array, array.T, rtol=1e-12, atol=1e-15 * np.abs(array).max()):
        raise InvalidParameterError(name, value, "must be symmetric")
    moments = np.linalg.eigvalsh(array)
    if moments[0] <= 0:
        raise InvalidParameterError(name, value, "must be positive definite")
    if moments[2] > moments[0] + moments[1] * (1 + 1e-12):
        raise InvalidParameterError(
            name, value,
            "principal moments must satisfy the triangle inequality I_max <= I_mid + I_min")
    return array
