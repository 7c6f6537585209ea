"""Checks applied where values enter the toolkit (files, flags, constructors).

Every failure raises :class:`InvalidParameterError`, a ``ValueError`` whose
one-line message names the parameter, the value it was given, and the rule it
broke, e.g. ``gyro_noise = -1.0: must be a finite number >= 0``.
"""
from __future__ import annotations

import math
import sys

import numpy as np

#: A standard deviation at or above this has a square (its variance) that
#: overflows a double: the square root of the largest double, 1.34e154.
MAX_STANDARD_DEVIATION = math.sqrt(sys.float_info.max)


class _Missing:
    """The value of a parameter that was not given (shown as such in a message)."""

    def __repr__(self) -> str:
        return "(not given)"


#: Stands for a value left out, e.g. the key that switches a section on.
MISSING = _Missing()


#: The longest text (a path) an error shows whole.
MAX_SHOWN_TEXT = 400


class InvalidParameterError(ValueError):
    """A parameter broke a rule; ``str(err)`` is a one-line explanation."""

    def __init__(self, name: str, value, rule: str):
        self.name = name
        self.value = value
        self.rule = rule
        super().__init__(f"{name} = {_show(value)}: {rule}")

    def __reduce__(self):
        """Pickled by its three parts (an exception pickles its message
        alone, which this constructor cannot take): raised in another
        process (a campaign's worker, a Dask cluster's), it reaches the
        caller as itself, one line, not as an unpickling error."""
        return type(self), (self.name, self.value, self.rule)


def _show(value) -> str:
    """``value`` as the error shows it: shortened to 80 characters, except a
    text (a file's path, a name) up to :data:`MAX_SHOWN_TEXT`, which a user
    needs whole to know what was refused."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    text = repr(value)
    limit = MAX_SHOWN_TEXT if isinstance(value, str) else 80
    return text if len(text) <= limit else text[:limit - 3] + "..."


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


def boolean(name: str, value) -> bool:
    """``value`` if it is a real boolean (Python's or numpy's); text such as
    ``"false"`` and numbers such as ``0`` are refused, not coerced."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidParameterError(name, value, "must be true or false (a boolean, not text "
                                    "or a number)")
    return bool(value)


def standard_deviation(name: str, value, *, strictly_positive: bool = False) -> float:
    """A standard deviation: a finite number >= 0 (or > 0) whose square is finite."""
    number = finite_number(name, value, minimum=0.0, strictly_positive=strictly_positive)
    _check_square(name, value, number)
    return number


def axis_standard_deviations(name: str, value, length: int = 3, *,
                             strictly_positive: bool = False) -> np.ndarray:
    """One standard deviation per axis (a number means the same on all), each
    >= 0 (or > 0 on every axis) with a finite square."""
    if np.ndim(value) == 0:
        return np.full(length, standard_deviation(name, value,
                                                  strictly_positive=strictly_positive))
    array = finite_vector(name, value, length)
    if strictly_positive and np.any(array <= 0):
        raise InvalidParameterError(name, value, "must be > 0 on every axis")
    if np.any(array < 0):
        raise InvalidParameterError(name, value, "must be >= 0")
    _check_square(name, value, float(array.max()))
    return array


def _check_square(name: str, value, largest: float) -> None:
    if not math.isfinite(largest * largest):
        raise InvalidParameterError(name, value, f"must be below {MAX_STANDARD_DEVIATION:.3g} "
                                    "so that its square (a variance) is finite")


def one_of(name: str, value, choices) -> str:
    """``value`` if it is one of ``choices``, else an error listing them."""
    if value not in choices:
        raise InvalidParameterError(name, value, f"must be one of {', '.join(choices)}")
    return value


def _not_a_number(value):
    """The rule a boolean, text or complex element of ``value`` (nested lists, tuples,
    arrays) breaks, or None: numpy would turn ``True`` into 1 and ``"2"`` into 2."""
    array = isinstance(value, np.ndarray)
    if isinstance(value, (bool, np.bool_)) or (array and value.dtype == bool):
        return "must be numbers, not true/false"
    if isinstance(value, (str, bytes)) or (array and value.dtype.kind in "SU"):
        return "must be numbers, not text"
    if isinstance(value, complex) or (array and value.dtype.kind == "c"):
        return "must be real numbers, not complex"
    items = value.ravel().tolist() if array and value.dtype == object else value
    if isinstance(items, (list, tuple)):
        return next(filter(None, map(_not_a_number, items)), None)
    return None


def float_array(name: str, value, rule: str) -> np.ndarray:
    """``value`` as a float array of any shape; ``rule`` says what it must be
    when it is not numbers. Booleans and text are refused, never converted."""
    wrong = _not_a_number(value)
    if wrong:
        raise InvalidParameterError(name, value, wrong)
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(name, value, rule) from None


def finite_vector(name: str, value, length: int) -> np.ndarray:
    """Return ``value`` as a float array of shape ``(length,)``."""
    array = float_array(name, value, f"must be a list of {length} numbers")
    if array.shape != (length,):
        raise InvalidParameterError(name, value, f"must be a list of {length} numbers")
    if not np.all(np.isfinite(array)):
        raise InvalidParameterError(name, value, "must be finite")
    return array


def unit_vector(name: str, value) -> np.ndarray:
    """``value``, a direction (3 finite numbers, not all zero), as a unit vector.

    Scaled by a power of two near its largest component before it is
    normalised: the norm of ``[1e300, 0, 0]`` overflows (and that of
    ``[1e-200, 0, 0]`` underflows) a double, which would make the direction
    zero or NaN. A power of two scales exactly, so an ordinary vector's unit
    vector is the same bits as ``v / |v|``."""
    vector = finite_vector(name, value, 3)
    largest = float(np.abs(vector).max())
    if largest == 0.0:
        raise InvalidParameterError(name, value, "must be a direction: 3 finite numbers, "
                                    "not all zero")
    scaled = np.ldexp(vector, -math.frexp(largest)[1])
    return scaled / np.linalg.norm(scaled)


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
    array = float_array(name, value, "must be a 3x3 matrix or 3 principal moments")
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
#: The largest body rate a measurement may report, per axis, rad/s: ten times
#: what a scenario's truth may turn at (100 rad/s), beyond any spacecraft or
#: hand-held IMU; a larger finite rate (1e300 rad/s) turns dead reckoning into NaN.
MAX_MEASURED_RATE_RADPS = 1000.0


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
    array = float_array(name, value, rule)
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
