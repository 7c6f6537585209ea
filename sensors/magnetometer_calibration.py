r"""The magnetometer's hard and soft iron, from a recording alone.

A magnetometer fixed to a device reads (:mod:`sensors.magnetometer`)

.. math:: m = S B + h + v,

with :math:`B` the field in the body frame, :math:`h` the hard iron (the
device's own constant field) and :math:`S` the soft iron (scale factors,
cross-coupling, the steel's distortion). Where the field is constant in
the world — one place, no magnet moving nearby — :math:`|B|` is constant
however the device turns, and the readings lie on the ellipsoid

.. math:: (m - h)^T (S S^T)^{-1} (m - h) = |B|^2 .

Fitting it needs no attitude and no reference (the attitude-independent
calibration of Alonso & Shuster, "Complete linear attitude-independent
magnetometer calibration", *J. Astronaut. Sci.* 50 (4), 2002). It gives
:math:`h` and :math:`S S^T`, not :math:`S`: a soft iron followed by a
rotation reads the same ellipsoid, so :math:`S` is taken symmetric (their
:math:`D = S - I` is symmetric for the same reason; what it leaves is a
fixed misalignment, which a filter sees as a mounting rotation). Without
the field's norm, :math:`S` is known up to a scale: it is taken with
determinant one (the soft iron stretches the field without changing the
volume of its ellipsoid).

Where the field's norm is known at every reading — a spacecraft, whose
orbit and field model give it — the hard iron alone is estimated from the
readings and those norms by TWOSTEP (:func:`twostep`).

The fit (:func:`fit_ellipsoid`): the algebraic least-squares quadric on
centred, scaled readings (the right singular vector of the smallest
singular value), which must be an ellipsoid, refined by scipy's
``least_squares`` on the geometric residual :math:`|W(m - h)| - 1`
(:math:`W` symmetric, the unit sphere's inverse soft iron). It is refused,
in one line, when the readings cannot determine it: too few directions
covered (:data:`MIN_COVERAGE` of :data:`DIRECTION_CELLS` equal cells of
the sphere; a turn about one axis reads a ring, on which a family of
ellipsoids fit, and on part of it the fit is biased), the fit's own
standard errors above :data:`MAX_RELATIVE_ERROR` of the field, or a field
that was not one field (residual above :data:`MAX_RESIDUAL`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from dynamics.validation import InvalidParameterError
from sensors.vector import readings_taken

#: Equal-area cells of the sphere whose share the readings' directions hit
#: is the coverage (a Fibonacci lattice: each direction in its nearest).
DIRECTION_CELLS = 60
#: The least coverage a fit is made from. One turn about an axis covers
#: about a fifth of the cells, on which a family of ellipsoids fit; on part
#: of the sphere the geometric fit is biased by the noise (simulated, the
#: field's norm scattered by 2 %: a hard iron off by 4.7 % of the field at
#: 62 % coverage, 1.3 % at 73 %, 0.4 % at 82 %).
MIN_COVERAGE = 0.7
#: The largest RMS of the calibrated field's norm about its mean, over it:
#: beyond it the field was not one field (a magnet or steel that moved
#: relative to the device; undisturbed hand-held recordings: 1.7 to 3.2 %).
MAX_RESIDUAL = 0.05
#: The largest standard error of the fitted hard iron (over the field's
#: norm) and of the soft iron's entries that a fit is accepted with.
MAX_RELATIVE_ERROR = 0.02
#: The fewest readings of a fit (nine unknowns and room to judge them).
MIN_READINGS = 50
#: The most readings the geometric refinement iterates on (evenly spaced
#: among them; its residuals and checks are over all): nine unknowns are
#: determined by far fewer, and an hour at 1 kHz took minutes.
MAX_FIT_READINGS = 20_000
#: The algebraic fit's coverage this far below :data:`MIN_COVERAGE` is
#: refused before the refinement (which moves it by a few cells).
COVERAGE_MARGIN = 0.1
#: The keys of a [recording.magnetometer] section that declare a calibration.
DECLARED = ("hard_iron", "soft_iron")


@dataclass(frozen=True)
class MagnetometerCalibration:
    """A fitted (or declared) calibration: ``field = inv(soft_iron) @
    (reading - hard_iron)``, in the readings' unit."""

    hard_iron: np.ndarray            # (3,), the readings' unit
    soft_iron: np.ndarray            # (3, 3), symmetric, dimensionless
    field_norm: float                # |B| after calibration, the readings' unit
    residual: float = 0.0            # RMS of |B| − field_norm, over field_norm
    coverage: float = 1.0            # share of the sphere's cells the readings hit
    readings: int = 0                # how many readings the fit read

    def apply(self, readings: np.ndarray) -> np.ndarray:
        """The field of each reading (a row of zeros, no reading, kept)."""
        readings = np.asarray(readings, dtype=float)
        field = np.linalg.solve(self.soft_iron, (readings - self.hard_iron).T).T
        return np.where(readings_taken(readings)[:, None], field, 0.0)

    def describe(self, unit: str = "uT") -> str:
        """One line: what was fitted, how well, from what."""
        scale = np.linalg.eigvalsh(self.soft_iron)
        return (f"hard iron [{', '.join(f'{v:.3g}' for v in self.hard_iron)}] {unit} "
                f"({np.linalg.norm(self.hard_iron) / self.field_norm:.1%} of the field's "
                f"{self.field_norm:.4g} {unit}), soft iron scale factors "
                f"{scale.min():.3f} to {scale.max():.3f}; residual {self.residual:.2%} of the "
                f"field over {self.readings:,} readings covering {self.coverage:.0%} of the "
                "directions")


def fit_ellipsoid(readings: np.ndarray, field_norm: float | None = None,
                  name: str = "magnetometer") -> MagnetometerCalibration:
    """The hard and soft iron of ``readings`` ((N, 3); rows of zeros, no
    reading, left out), scaled to ``field_norm`` where it is known (the
    site's field, in the readings' unit) or to a soft iron of determinant
    one; :class:`InvalidParameterError` naming ``name`` where the readings
    cannot determine it."""
    if field_norm is not None and (isinstance(field_norm, bool) or
                                   not isinstance(field_norm, (int, float)) or
                                   not (math.isfinite(field_norm) and field_norm > 0)):
        raise InvalidParameterError(f"{name} field_norm", field_norm, "must be a positive number")
    readings = np.asarray(readings, dtype=float)
    readings = readings[readings_taken(readings) & np.all(np.isfinite(readings), axis=1)]
    if len(readings) < MIN_READINGS:
        raise InvalidParameterError(name, f"{len(readings)} readings",
                                    f"an ellipsoid fit needs at least {MIN_READINGS}")
    hard, inverse = _algebraic(readings, name)
    covered = coverage((readings - hard) @ inverse)
    if covered < MIN_COVERAGE - COVERAGE_MARGIN:
        raise InvalidParameterError(name, f"{covered:.0%} of the directions", _TURN_MORE)
    stride = -(-len(readings) // MAX_FIT_READINGS)
    hard, inverse = _refined(readings[::stride], hard, inverse)
    unit_field = (readings - hard) @ inverse
    unit_residual = np.linalg.norm(unit_field, axis=1) - 1.0
    covered = coverage(unit_field)
    if covered < MIN_COVERAGE:
        raise InvalidParameterError(name, f"{covered:.0%} of the directions", _TURN_MORE)
    _check_determined(readings, hard, inverse, unit_residual, name)
    residual = float(np.sqrt(np.mean(unit_residual ** 2)))
    if residual > MAX_RESIDUAL:
        raise InvalidParameterError(name, f"a residual of {residual:.1%} of the field",
                                    f"must be within {MAX_RESIDUAL:.0%}: the field was not "
                                    "constant (a magnet or steel moved relative to the device); "
                                    "calibrate on a recording away from both")
    radius = field_norm if field_norm is not None else np.linalg.det(inverse) ** (-1.0 / 3.0)
    return MagnetometerCalibration(
        hard_iron=hard, soft_iron=np.linalg.inv(inverse) / radius, field_norm=float(radius),
        residual=residual, coverage=covered,
        readings=len(readings))


_TURN_MORE = (f"an ellipsoid fit needs readings in at least {MIN_COVERAGE:.0%} of the "
              "directions: turn the device through every orientation while it logs")


def coverage(vectors: np.ndarray) -> float:
    """The share of :data:`DIRECTION_CELLS` equal cells of the sphere in
    which ``vectors``' directions fall."""
    cells = fibonacci_sphere(DIRECTION_CELLS)
    hit = np.zeros(DIRECTION_CELLS, dtype=bool)
    for start in range(0, len(vectors), 50_000):
        hit[np.argmax(vectors[start:start + 50_000] @ cells.T, axis=1)] = True
    return float(hit.mean())


def fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` nearly equally spaced unit vectors (a Fibonacci lattice)."""
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * index
    ring = np.sqrt(1.0 - z * z)
    return np.column_stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z])


def _algebraic(readings: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(h, W)`` of the algebraic least-squares quadric: the smallest
    singular vector of the design matrix of centred, scaled readings."""
    centre = readings.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum((readings - centre) ** 2, axis=1))))
    if not scale > 1e-9 * max(float(np.abs(centre).max()), 1e-300):
        raise InvalidParameterError(name, "the readings", "are all the same: " + _TURN_MORE)
    x, y, z = ((readings - centre) / scale).T
    design = np.column_stack([x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y,
                              2 * x, 2 * y, 2 * z, np.ones_like(x)])
    a, b, c, d, e, f, g, h, i, j = np.linalg.svd(design, full_matrices=False)[2][-1]
    quadric = np.array([[a, f, e], [f, b, d], [e, d, c]])
    try:
        centre_unit = -np.linalg.solve(quadric, [g, h, i])
    except np.linalg.LinAlgError:
        raise InvalidParameterError(name, "the readings", _TURN_MORE) from None
    shape = quadric / (centre_unit @ quadric @ centre_unit - j)
    values, vectors = np.linalg.eigh(shape)
    if values.min() <= 0:
        raise InvalidParameterError(name, "the readings", "do not lie on an ellipsoid (a "
                                    "magnet moving with the device, or too few directions): "
                                    + _TURN_MORE)
    inverse = vectors @ np.diag(np.sqrt(values)) @ vectors.T / scale
    return centre + scale * centre_unit, inverse


_UPPER = np.triu_indices(3)


def _refined(readings: np.ndarray, hard: np.ndarray, inverse: np.ndarray):
    """``(h, W)`` minimising the geometric residuals |W(m − h)| − 1 (W
    symmetric: its upper triangle is the unknown), by scipy's Levenberg–
    Marquardt from the algebraic fit."""
    from scipy.optimize import least_squares

    def unpack(p):
        upper = np.zeros((3, 3))
        upper[_UPPER] = p[3:]
        return p[:3], upper + np.triu(upper, 1).T

    def residual(p):
        h, w = unpack(p)
        return np.linalg.norm((readings - h) @ w, axis=1) - 1.0

    start = np.concatenate([hard, inverse[_UPPER]])
    found = least_squares(residual, start, jac=lambda p: _jacobian(readings, *unpack(p)),
                          method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    return unpack(found.x)


def _jacobian(readings, hard, inverse) -> np.ndarray:
    """The residuals' derivatives by h and by W's upper triangle."""
    offsets = readings - hard
    v = offsets @ inverse
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    columns = [-(v @ inverse) / norm]
    for i, j in zip(*_UPPER):
        pair = v[:, i] * offsets[:, j] + (v[:, j] * offsets[:, i] if i != j else 0.0)
        columns.append(pair[:, None] / norm)
    return np.hstack(columns)


def _check_determined(readings, hard, inverse, residual, name: str) -> None:
    """Refuse a fit whose standard errors (σ² (JᵀJ)⁻¹, σ from the residual)
    exceed :data:`MAX_RELATIVE_ERROR` of the field's norm (hard iron) or of
    the soft iron's scale (its inverse's entries)."""
    jac = _jacobian(readings, hard, inverse)
    variance = float(residual @ residual) / max(len(readings) - 9, 1)
    information = jac.T @ jac
    # Its condition on columns scaled to one: free of the readings' unit.
    size = np.sqrt(np.diag(information))
    if not np.all(size > 0) or np.linalg.cond(information / np.outer(size, size)) > 1e12:
        raise InvalidParameterError(name, "the readings", _TURN_MORE)
    errors = np.sqrt(np.maximum(np.diag(np.linalg.inv(information)) * variance, 0.0))
    radius = np.linalg.det(inverse) ** (-1.0 / 3.0)
    relative = max(errors[:3].max() / radius, errors[3:].max() * radius)
    if relative > MAX_RELATIVE_ERROR:
        raise InvalidParameterError(name, f"a fit uncertain to {relative:.1%} of the field",
                                    f"must be within {MAX_RELATIVE_ERROR:.0%}: "
                                    + _TURN_MORE)


def calibrated(readings: np.ndarray, section: dict, unit: float, where: str) -> np.ndarray:
    """The readings (µT) of a ``[recording.magnetometer]`` ``section``
    (``where`` names it in errors), calibrated as it says: ``calibrate =
    true`` fits the calibration to them (said in a note); ``hard_iron`` (3
    numbers, in the section's unit, ``unit`` µT each) and ``soft_iron`` (3 ×
    3) declare it; neither, none."""
    fit = section.get("calibrate", False)
    if not isinstance(fit, bool):
        raise InvalidParameterError(f"{where}.calibrate", fit, "must be true or false")
    declared = [key for key in DECLARED if key in section]
    if fit and declared:
        raise InvalidParameterError(f"{where}.{declared[0]}", section[declared[0]],
                                    "is declared beside calibrate = true, which fits it: "
                                    "give one or the other")
    if fit:
        try:
            found = fit_ellipsoid(readings, name=f"{where}.calibrate")
        except InvalidParameterError as err:      # the rule is the fit's, not the key's
            raise InvalidParameterError(f"{where}.calibrate", True, f"cannot be done on these "
                                        f"readings ({err.value}): {err.rule}") from None
        warnings.warn(f"{where}: calibrated by an ellipsoid fit: {found.describe('uT')}",
                      stacklevel=2)
        return found.apply(readings)
    if not declared:
        return readings
    hard = _declared(f"{where}.hard_iron", section.get("hard_iron", [0.0] * 3), (3,))
    soft = _declared(f"{where}.soft_iron", section.get("soft_iron", np.eye(3).tolist()), (3, 3))
    if not abs(np.linalg.det(soft)) > 1e-6:
        raise InvalidParameterError(f"{where}.soft_iron", section["soft_iron"],
                                    "must be invertible")
    return MagnetometerCalibration(hard * unit, soft, 1.0).apply(readings)


def declares_calibration(section: dict) -> bool:
    """Whether a ``[recording.magnetometer]`` section applies a calibration
    (:func:`calibrated`): ``calibrate = true``, or a declared hard or soft
    iron."""
    return section.get("calibrate") is True or any(key in section for key in DECLARED)


def _declared(key: str, value, shape: tuple) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != shape or not np.all(np.isfinite(array)):
        raise InvalidParameterError(key, value, f"must be {' × '.join(map(str, shape))} "
                                    "finite numbers")
    return array


def twostep(readings: np.ndarray, field_norms: np.ndarray,
            sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """``(b, P)``: the magnetometer's hard iron and its covariance from
    ``readings`` (N, 3) and the field's norm at each (N,), both in one unit,
    with white noise of ``sigma`` per axis — no attitude: Alonso & Shuster,
    "TWOSTEP: A fast robust algorithm for attitude-independent
    magnetometer-bias determination", *J. Astronaut. Sci.* 50 (4), 2002.

    Each reading gives :math:`z_k = |B_k|^2 - |H_k|^2 = 2 B_k \\cdot b -
    |b|^2 + v_k`, its noise of mean :math:`\\mu = -3\\sigma^2` and variance
    :math:`\\sigma_k^2 = 4\\sigma^2 |B_k - b|^2 + 6\\sigma^4` (their eqs. for
    isotropic noise). Step one, the centred estimate: the weighted means of
    :math:`z_k` and :math:`B_k` taken out, the :math:`|b|^2` term goes and
    the rest is linear in :math:`b`. Step two: Gauss–Newton on the whole
    likelihood from it (scipy's ``least_squares``), :math:`P` the inverse
    of its Fisher information :math:`\\sum_k 4 (B_k - b)(B_k - b)^T /
    \\sigma_k^2`."""
    from scipy.optimize import least_squares
    readings = np.asarray(readings, dtype=float)
    z = np.sum(readings ** 2, axis=1) - np.asarray(field_norms, dtype=float) ** 2 \
        + 3.0 * sigma ** 2

    def variance(offsets):           # σ_k² of each z_k, b taken off the readings
        return 4.0 * sigma ** 2 * np.sum(offsets ** 2, axis=1) + 6.0 * sigma ** 4

    # Step one: weights 1/σ_k² (with b = 0 in σ_k), the weighted means out.
    weights = 1.0 / variance(readings)
    share = weights / weights.sum()
    centred, z_centred = readings - share @ readings, z - share @ z
    start = np.linalg.solve(4.0 * (centred * weights[:, None]).T @ centred,
                            2.0 * (centred * (weights * z_centred)[:, None]).sum(axis=0))

    def residual(b):
        return (z - 2.0 * readings @ b + b @ b) / np.sqrt(variance(readings - b))

    bias = least_squares(residual, start, method="lm", xtol=1e-12, ftol=1e-12).x
    offsets = readings - bias
    fisher = 4.0 * (offsets / variance(offsets)[:, None]).T @ offsets
    return bias, np.linalg.inv(fisher)
