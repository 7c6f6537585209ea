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


def one_of(name: str, value, choices) -> str:
    """``value`` if it is one of ``choices``, else an error listing them."""
    if value not in choices:
        raise InvalidParameterError(name, value, f"must be one of {', '.join(choices)}")
    return value


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
    largest = float(np.abs(q).max())
    # Scale by the largest component first: |q| of [1e300, 1e300, 0, 0] overflows.
    norm = largest * float(np.linalg.norm(q / largest)) if largest > 0 else 0.0
    if norm < 1e-12:
        raise InvalidParameterError(name, value, "must be a non-zero quaternion [w, x, y, z]")
    return (q / largest) / (norm / largest)


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


#: exp(x) overflows a double above this (ln of the largest double, 709.78).
MAX_EXPONENT = 709.0
#: Seeds are stored as int64 and fed to numpy's SeedSequence.
MAX_SEED = 2 ** 63 - 1


def process_exponent(name: str, value) -> float:
    """A natural exponent ``x`` with ``exp(x)`` a positive, finite double."""
    number = finite_number(name, value)
    if number > MAX_EXPONENT:
        raise InvalidParameterError(name, value, f"must be <= {MAX_EXPONENT:g} so that "
                                    "exp(pc_exponent) is finite")
    if math.exp(number) == 0.0:
        raise InvalidParameterError(name, value, "must be > -745 so that exp(pc_exponent) > 0")
    return number


def seed_values(name: str, value) -> np.ndarray:
    """Whole-number seeds in [0, 2⁶³ - 1] as an int64 array (any shape)."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, "must be whole numbers >= 0") from None
    if array.dtype == bool or not (np.issubdtype(array.dtype, np.integer)
                                   or np.issubdtype(array.dtype, np.floating)
                                   or array.dtype == object):
        raise InvalidParameterError(name, value, "must be whole numbers >= 0")
    items = array.ravel().tolist()
    for item in items:
        if isinstance(item, bool) or not isinstance(item, (int, float)) or \
                (isinstance(item, float) and not item.is_integer()):
            raise InvalidParameterError(name, item, "must be a whole number >= 0")
        if not 0 <= item <= MAX_SEED:
            raise InvalidParameterError(name, item, f"must be a whole number from 0 to "
                                        f"2^63 - 1 = {MAX_SEED}")
    return np.array([int(item) for item in items], dtype=np.int64).reshape(array.shape)


def covariance_matrix(name: str, value, size: int = 4) -> np.ndarray:
    """A ``size`` x ``size`` symmetric positive definite matrix from a scalar
    (times the identity), a diagonal of ``size`` values, or the matrix itself."""
    rule = f"must be a number, {size} numbers or a {size}x{size} matrix"
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, rule) from None
    if array.ndim == 0:
        array = array * np.eye(size)
    elif array.shape == (size,):
        array = np.diag(array)
    if array.shape != (size, size):
        raise InvalidParameterError(name, value, rule)
    if not np.all(np.isfinite(array)):
        raise InvalidParameterError(name, value, "must be finite")
    if not np.allclose(array, array.T):
        raise InvalidParameterError(name, value, "must be symmetric")
    if np.linalg.eigvalsh(array)[0] <= 0:
        raise InvalidParameterError(name, value, "must be positive definite")
    return array
