r"""What the spacecraft's vector sensors see: the Sun, the Earth's shadow, the
geomagnetic field, and (on the ground) gravity.

**The Sun** (:func:`sun_position_km`): the Astronomical Almanac's
low-precision formula (*The Astronomical Almanac*, section C, "Low precision
formulas for the Sun"; 0.01° from 1950 to 2050). With :math:`n` days from
J2000.0,

.. math::

    L = 280.460° + 0.9856474°\,n, \qquad g = 357.528° + 0.9856003°\,n, \\
    \lambda = L + 1.915° \sin g + 0.020° \sin 2g, \qquad
    \epsilon = 23.439° - 0.0000004°\,n, \\
    R = 1.00014 - 0.01671 \cos g - 0.00014 \cos 2g \ \text{AU},

and the geocentric direction :math:`(\cos\lambda, \cos\epsilon\sin\lambda,
\sin\epsilon\sin\lambda)` in the equator and equinox of date (the frame of
:mod:`dynamics.orbit`). The spacecraft-to-Sun direction differs from it by
at most the parallax of the orbit, :math:`a / R \approx 10^{-4.3}` rad for
LEO; it is computed from the difference of the two positions all the same.

**The Earth's shadow** (:func:`illumination`), two models (Montenbruck &
Gill, *Satellite Orbits*, 2000, §3.4.2):

* ``"cylindrical"``: the shadow is a cylinder of the Earth's radius behind
  it; the spacecraft is lit (1) or not (0).
* ``"conical"``: the Sun and the Earth as discs of apparent radii
  :math:`a = \arcsin(R_\odot / |s - r|)` and :math:`b = \arcsin(R_E / |r|)`
  at separation :math:`c`; the lit fraction of the Sun's disc is 1 for
  :math:`c \ge a + b`, 0 in the umbra (:math:`c \le b - a`), and the
  overlap of the discs' areas between (the penumbra).

**The geomagnetic field** (:func:`geomagnetic_field_nT`): the International
Geomagnetic Reference Field (IGRF-14, the 2024 generation of the model Alken
et al. 2021 describe for IGRF-13; its coefficients ship with ``ppigrf``) evaluated in geocentric spherical
coordinates (``ppigrf.igrf_gc``) and rotated back to TEME; or, as a fast
option, the tilted dipole of its first three coefficients
(:math:`g_1^0, g_1^1, h_1^1`):

.. math:: B(r) = \frac{R_E^3}{|r|^3}\bigl(3 (m \cdot \hat r)\hat r - m\bigr),
          \qquad m = (g_1^1, h_1^1, g_1^0) \ \text{(nT, Earth-fixed)}.

The field's secular variation over a run is neglected: the coefficients are
those of the epoch (a few nT a year). IGRF-14 spans 1900-2030 (its last
five years the predicted secular variation); an epoch outside is held at
the nearer end, and said so once as a warning (:func:`igrf_date`).

**On the ground** (:func:`local_level_field_nT`) the reference frame is
east-north-up. At a pole east and north are undefined; this toolkit takes
the limit along the meridian of the site's longitude λ: north is the
direction along that meridian (away from λ at the North Pole, towards it at
the South Pole), east 90° clockwise from it seen from above, up the
vertical: the frame of a site a hair's breadth from the pole on that meridian.
"""
from __future__ import annotations

import contextlib
import io
import math
import warnings
from datetime import datetime
from functools import lru_cache

import numpy as np

from dynamics.orbit import EARTH_RADIUS_KM, JD_J2000, ecef_to_teme, teme_to_ecef
from dynamics.validation import one_of

#: The astronomical unit, km (IAU 2012).
AU_KM = 149597870.7
#: The Sun's radius, km (IAU 2015 nominal).
SUN_RADIUS_KM = 695700.0
#: Standard gravity, m/s² (what an accelerometer at rest reads, upward).
STANDARD_GRAVITY_MPS2 = 9.80665
SHADOW_MODELS = ("conical", "cylindrical")
FIELD_MODELS = ("igrf", "dipole")


def sun_position_km(jd: np.ndarray) -> np.ndarray:
    """``(N, 3)`` geocentric position of the Sun in the frame of date, km
    (the Astronomical Almanac's low-precision formula, module docstring)."""
    n = np.asarray(jd, dtype=float) - JD_J2000
    mean_longitude = np.radians(280.460 + 0.9856474 * n)
    g = np.radians(357.528 + 0.9856003 * n)
    ecliptic_longitude = mean_longitude + np.radians(1.915 * np.sin(g) + 0.020 * np.sin(2 * g))
    obliquity = np.radians(23.439 - 0.0000004 * n)
    distance_km = (1.00014 - 0.01671 * np.cos(g) - 0.00014 * np.cos(2 * g)) * AU_KM
    return distance_km[..., None] * np.stack([
        np.cos(ecliptic_longitude),
        np.cos(obliquity) * np.sin(ecliptic_longitude),
        np.sin(obliquity) * np.sin(ecliptic_longitude)], axis=-1)


def sun_right_ascension_declination_deg(jd: float) -> tuple[float, float]:
    """The Sun's right ascension and declination of date, degrees."""
    x, y, z = sun_position_km(np.array([jd]))[0]
    return (math.degrees(math.atan2(y, x)) % 360.0,
            math.degrees(math.atan2(z, math.hypot(x, y))))


def illumination(position_km: np.ndarray, sun_km: np.ndarray, model: str = "conical"
                 ) -> np.ndarray:
    """``(N,)`` fraction of the Sun's disc seen from ``position_km`` (TEME, km)
    past the Earth: 1 in sunlight, 0 in the umbra (module docstring)."""
    one_of("shadow_model", model, SHADOW_MODELS)
    r = np.asarray(position_km, dtype=float)
    to_sun = np.asarray(sun_km, dtype=float) - r
    r_norm = np.linalg.norm(r, axis=-1)
    to_sun_norm = np.linalg.norm(to_sun, axis=-1)
    if model == "cylindrical":
        sun_unit = sun_km / np.linalg.norm(sun_km, axis=-1, keepdims=True)
        along = np.sum(r * sun_unit, axis=-1)
        across = np.linalg.norm(r - along[..., None] * sun_unit, axis=-1)
        return np.where((along < 0) & (across < EARTH_RADIUS_KM), 0.0, 1.0)
    a = np.arcsin(SUN_RADIUS_KM / to_sun_norm)
    b = np.arcsin(EARTH_RADIUS_KM / r_norm)
    c = np.arccos(np.clip(-np.sum(r * to_sun, axis=-1) / (r_norm * to_sun_norm), -1.0, 1.0))
    lit = np.ones_like(c)
    partial = (c < a + b) & (c > np.abs(a - b))
    c_safe = np.where(partial, c, 1.0)     # the overlap's formula, where the discs overlap
    x = (c_safe * c_safe + a * a - b * b) / (2.0 * c_safe)
    y = np.sqrt(np.maximum(a * a - x * x, 0.0))
    overlap = (a * a * np.arccos(np.clip(x / a, -1, 1)) + b * b * np.arccos(
        np.clip((c_safe - x) / b, -1, 1)) - c_safe * y)
    lit = np.where(partial, 1.0 - overlap / (np.pi * a * a), lit)
    return np.where(c <= b - a, 0.0, lit)


@lru_cache(maxsize=1)
def igrf_span() -> tuple[datetime, datetime]:
    """The first and last dates of the IGRF coefficients ``ppigrf`` ships
    (IGRF-14: 1900-01-01 to 2030-01-01), naive UTC."""
    from ppigrf import ppigrf as module
    g, _ = module.read_shc(module.shc_fn)
    return g.index[0].to_pydatetime(), g.index[-1].to_pydatetime()


def igrf_date(date: datetime) -> datetime:
    """``date`` (naive UTC) as IGRF takes it: within its span, or held at the
    nearer end with a warning (the field then is that end's, not the date's).
    ``ppigrf`` would print its own notice on standard output past the end
    and give NaN before the start."""
    day = date.replace(tzinfo=None)
    first, last = igrf_span()
    if first <= day <= last:
        return day
    end = first if day < first else last
    # Issued from this one line (not the caller's): Python's filter then says
    # it once, however many places ask for the same date.
    warnings.warn(f"the epoch {day:%Y-%m-%d} is outside IGRF's {first:%Y}-{last:%Y}: the "
                  f"geomagnetic field is that of {end:%Y-%m-%d}, not of the epoch (it drifts "
                  "by tens of nT a year)", stacklevel=1)
    return end


def _ppigrf(function, *args, **keywords):
    """A ``ppigrf`` call with its prints kept off standard output (where a
    command's tables go): anything it prints becomes a warning instead."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        result = function(*args, **keywords)
    text = " ".join(printed.getvalue().split())
    if text:
        warnings.warn(f"ppigrf: {text}", stacklevel=3)
    return result


def _igrf_ecef_nT(position_ecef_km: np.ndarray, date: datetime) -> np.ndarray:
    """IGRF in the Earth-fixed frame, nT (``ppigrf.igrf_gc``: geocentric r,
    colatitude, longitude in, (B_r, B_θ, B_φ) out)."""
    import ppigrf
    x, y, z = np.asarray(position_ecef_km, dtype=float).T
    r = np.sqrt(x * x + y * y + z * z)
    colatitude = np.arccos(z / r)
    longitude = np.arctan2(y, x)
    b_r, b_theta, b_phi = (np.ravel(component) for component in _ppigrf(
        ppigrf.igrf_gc, r, np.degrees(colatitude), np.degrees(longitude), igrf_date(date)))
    st, ct, sp, cp = np.sin(colatitude), np.cos(colatitude), np.sin(longitude), np.cos(longitude)
    return np.stack([b_r * st * cp + b_theta * ct * cp - b_phi * sp,
                     b_r * st * sp + b_theta * ct * sp + b_phi * cp,
                     b_r * ct - b_theta * st], axis=-1)


def dipole_moment_nT(date: datetime) -> np.ndarray:
    """The tilted dipole of IGRF at ``date``: its degree-1 coefficients
    ``(g11, h11, g10)`` in nT, Earth-fixed, read off IGRF truncated at degree
    1 on the equator (where :math:`B_r = 2 (g_1^1 \\cos\\phi + h_1^1
    \\sin\\phi)` and :math:`B_\\theta = g_1^0`)."""
    import ppigrf
    b_r, b_theta, _ = (np.ravel(v) for v in _ppigrf(
        ppigrf.igrf_gc, np.full(2, EARTH_RADIUS_KM), np.full(2, 90.0), np.array([0.0, 90.0]),
        igrf_date(date), max_degree=1))
    return np.array([b_r[0] / 2.0, b_r[1] / 2.0, b_theta[0]])


def _dipole_ecef_nT(position_ecef_km: np.ndarray, moment_nT: np.ndarray) -> np.ndarray:
    """The dipole field ``(R_E/|r|)³ (3 (m·r̂) r̂ − m)``, ``m = (g11, h11, g10)``
    Earth-fixed: minus the gradient of the degree-1 potential
    ``R_E³ (m · r) / |r|³``."""
    r = np.asarray(position_ecef_km, dtype=float)
    r_norm = np.linalg.norm(r, axis=-1, keepdims=True)
    unit = r / r_norm
    return (EARTH_RADIUS_KM / r_norm) ** 3 * (3.0 * (unit @ moment_nT)[..., None] * unit
                                              - moment_nT)


def geomagnetic_field_nT(position_km: np.ndarray, jd: np.ndarray, date: datetime,
                         model: str = "igrf") -> np.ndarray:
    """``(N, 3)`` geomagnetic field at TEME positions (km) and Julian dates,
    in TEME, nT: IGRF or its tilted dipole (module docstring)."""
    one_of("magnetic_field_model", model, FIELD_MODELS)
    ecef = teme_to_ecef(position_km, jd)
    field = (_igrf_ecef_nT(ecef, date) if model == "igrf"
             else _dipole_ecef_nT(ecef, dipole_moment_nT(date)))
    return ecef_to_teme(field, jd)


def local_level_field_nT(latitude_deg: float, longitude_deg: float, altitude_km: float,
                         date: datetime) -> np.ndarray:
    """IGRF at a place on the ground, in the local east-north-up frame, nT
    (``ppigrf.igrf``, geodetic coordinates); at a pole, in the frame of the
    limit along the site's meridian (module docstring)."""
    import ppigrf
    day = igrf_date(date)
    if abs(latitude_deg) != 90.0:
        east, north, up = (float(np.ravel(v)[0]) for v in _ppigrf(
            ppigrf.igrf, longitude_deg, latitude_deg, altitude_km, day))
        return np.array([east, north, up])
    # At the pole ppigrf's east component is 0/0 (B_φ carries 1/sin θ), but
    # its north and up, along any meridian, are the limits along it. East
    # along the meridian λ is north along the meridian λ - 90° at the North
    # Pole, λ + 90° at the South Pole: the same horizontal direction.
    turned = longitude_deg - math.copysign(90.0, latitude_deg)
    with np.errstate(invalid="ignore", divide="ignore"):
        _, north, up = (np.ravel(v) for v in _ppigrf(
            ppigrf.igrf, np.array([longitude_deg, turned]), latitude_deg, altitude_km, day))
    return np.array([float(north[1]), float(north[0]), float(up[0])])


class References:
    """The reference vectors a scenario's vector sensors see at each step.

    Attributes
    ----------
    magnetic_field_nT : (N, 3) the geomagnetic field, reference frame, nT
    sun_unit : (N, 3) the spacecraft-to-Sun unit vector, or None on the ground
    illumination : (N,) the lit fraction of the Sun's disc (:func:`illumination`)
    position_km : (N, 3) the spacecraft's TEME position, or None on the ground
    """

    def __init__(self, magnetic_field_nT, sun_unit=None, illumination=None, position_km=None):
        self.magnetic_field_nT = magnetic_field_nT
        self.sun_unit = sun_unit
        n = len(magnetic_field_nT)
        self.illumination = np.zeros(n) if illumination is None else illumination
        self.position_km = position_km

    @property
    def eclipse(self) -> np.ndarray:
        """``(N,)`` bool: the steps in the Earth's shadow (umbra or penumbra)."""
        return self.illumination < 1.0


def orbit_references(orbit, epoch: datetime, time_s: np.ndarray, field_model: str = "igrf",
                     shadow_model: str = "conical") -> References:
    """The field, the Sun and the shadow along ``orbit`` at ``time_s`` after ``epoch``."""
    from dynamics.orbit import julian_date
    jd = julian_date(epoch) + np.asarray(time_s, dtype=float) / 86400.0
    position = orbit.positions_km(time_s)
    sun = sun_position_km(jd)
    to_sun = sun - position
    return References(magnetic_field_nT=geomagnetic_field_nT(position, jd, epoch, field_model),
                      sun_unit=to_sun / np.linalg.norm(to_sun, axis=1, keepdims=True),
                      illumination=illumination(position, sun, shadow_model),
                      position_km=position)


def site_references(latitude_deg: float, longitude_deg: float, altitude_km: float,
                    epoch: datetime, n_steps: int) -> References:
    """On the ground, in the local east-north-up frame (the Earth's rotation,
    15°/h, neglected over a recording): the site's constant IGRF field."""
    field = local_level_field_nT(latitude_deg, longitude_deg, altitude_km, epoch)
    return References(magnetic_field_nT=np.broadcast_to(field, (n_steps, 3)).copy())
