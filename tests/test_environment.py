"""The orbit and the environment against published values and the geometry."""
import math
from datetime import datetime, timezone

import numpy as np
import pytest

from dynamics.environment import (EARTH_RADIUS_KM, _dipole_ecef_nT, dipole_moment_nT,
                                  geomagnetic_field_nT, illumination, local_level_field_nT,
                                  orbit_references, sun_position_km,
                                  sun_right_ascension_declination_deg)
from dynamics.orbit import (CircularOrbit, TLEOrbit, ecef_to_teme, gmst_rad, julian_date,
                            teme_to_ecef)
from dynamics.validation import InvalidParameterError

UTC = timezone.utc


def test_sun_direction_matches_meeus_example_25a_within_a_hundredth_of_a_degree():
    # Meeus, Astronomical Algorithms (2nd ed., 1998), example 25.a: 1992 October
    # 13.0 TD (JDE 2448908.5), the Sun's apparent right ascension 13h13m31.4s =
    # 198.38083°, declination -7°47'06" = -7.78500°. The Almanac's low-precision
    # formula claims 0.01° (it gives 198.3753°, -7.7828°).
    ra, dec = sun_right_ascension_declination_deg(2448908.5)
    assert abs(ra - 198.380833) < 0.01
    assert abs(dec - -7.785) < 0.01


def test_sun_distance_is_the_almanac_s_radius_vector():
    # Perihelion (early January) about 0.9833 AU, aphelion (early July) 1.0167 AU.
    january = np.linalg.norm(sun_position_km(np.array([julian_date(datetime(2026, 1, 3,
                                                                              tzinfo=UTC))])))
    july = np.linalg.norm(sun_position_km(np.array([julian_date(datetime(2026, 7, 5,
                                                                           tzinfo=UTC))])))
    assert january / 149597870.7 == pytest.approx(0.9833, abs=2e-4)
    assert july / 149597870.7 == pytest.approx(1.0167, abs=2e-4)


def test_igrf_at_80_north_matches_the_noaa_calculator():
    # NOAA NCEI's calculator (IGRF-13, "IGRF2020", version 0.5.1.11), as stored
    # in ppigrf's own test data: 80° N, 0° E, 5 km above the WGS-84 ellipsoid,
    # 2020-01-01: X (north) 6560.4, Y (east) -151.6, Z (down) 54497.7 nT.
    # ppigrf ships IGRF-14, whose definitive 2020 model differs from IGRF-13's
    # by a few nT: 25 nT is the tolerance.
    east, north, up = local_level_field_nT(80.0, 0.0, 5.0, datetime(2020, 1, 1, tzinfo=UTC))
    assert north == pytest.approx(6560.4, abs=25)
    assert east == pytest.approx(-151.6, abs=25)
    assert -up == pytest.approx(54497.7, abs=25)


def test_the_dipole_is_igrf_truncated_at_degree_one_and_igrf_near_it():
    date = datetime(2026, 3, 20, 12, tzinfo=UTC)
    moment = dipole_moment_nT(date)
    assert moment[2] == pytest.approx(-29240, abs=100)     # g10 in 2026, about -29240 nT
    positions = np.array([[7000.0, 100.0, 300.0], [100.0, -6900.0, 2000.0],
                          [2000.0, 3000.0, -6000.0]])
    jd = np.full(3, julian_date(date))
    igrf = geomagnetic_field_nT(positions, jd, date, "igrf")
    dipole = geomagnetic_field_nT(positions, jd, date, "dipole")
    # The higher degrees are tens of percent of the field at LEO: the two
    # agree in size to that, and the dipole's direction to tens of degrees.
    ratio = np.linalg.norm(dipole, axis=1) / np.linalg.norm(igrf, axis=1)
    assert np.all((ratio > 0.7) & (ratio < 1.3))
    cosine = np.sum(igrf * dipole, axis=1) / np.linalg.norm(igrf, axis=1) / \
        np.linalg.norm(dipole, axis=1)
    assert np.all(cosine > math.cos(math.radians(30)))
    # Exactly the degree-1 field: at the equator, B_r = 2 g11 and B_theta = g10.
    equator = np.array([[EARTH_RADIUS_KM, 0.0, 0.0]])
    b = _dipole_ecef_nT(equator, moment)[0]
    assert b[0] == pytest.approx(2 * moment[0], rel=1e-12)
    assert -b[2] == pytest.approx(moment[2], rel=1e-12)


def test_teme_and_the_earth_fixed_frame_round_trip_and_gmst_at_j2000():
    # GMST at J2000.0 (2000 January 1, 12h UT1) is 280.46061837° (Vallado 2013, eq. 3-47).
    assert math.degrees(gmst_rad(2451545.0)) == pytest.approx(280.46061837, abs=1e-6)
    rng = np.random.default_rng(5)
    v = rng.standard_normal((10, 3))
    jd = 2461000.0 + rng.uniform(0, 1, 10)
    assert np.allclose(ecef_to_teme(teme_to_ecef(v, jd), jd), v, atol=1e-12)


def _equatorial_orbit_at_equinox(altitude_km=500.0):
    epoch = datetime(2026, 3, 20, 14, 46, tzinfo=UTC)      # the March equinox: declination ≈ 0
    return CircularOrbit(altitude_km, 0.0, 0.0, 0.0, epoch), epoch


def test_cylindrical_eclipse_lasts_as_the_geometry_says():
    # In an orbit whose plane holds the Sun, the cylinder's shadow spans
    # 2 asin(R_E / a) of the orbit (both edges found to a 1 s step), crossed at
    # the equatorial orbit's rate, the mean motion plus the node's J2 drift.
    orbit, epoch = _equatorial_orbit_at_equinox()
    time_s = np.arange(0.0, orbit.period_s, 1.0)
    refs = orbit_references(orbit, epoch, time_s, "dipole", "cylindrical")
    shadow = refs.illumination == 0.0
    expected_s = 2 * math.asin(EARTH_RADIUS_KM / orbit.radius_km) / (
        orbit.mean_motion_radps + orbit.node_rate_radps)
    sun_declination = sun_right_ascension_declination_deg(julian_date(epoch))[1]
    assert abs(sun_declination) < 0.05      # the Sun in the orbit's plane, to 0.05°
    assert shadow.sum() == pytest.approx(expected_s, abs=2.0)
    # One contiguous shadow, centred where the spacecraft is opposite the Sun.
    steps = np.flatnonzero(shadow)
    assert np.all(np.diff(steps) == 1)
    middle = refs.position_km[steps[len(steps) // 2]]
    assert np.dot(middle, refs.sun_unit[steps[len(steps) // 2]]) / np.linalg.norm(middle) < -0.999


def test_conical_shadow_brackets_the_cylinder_with_its_penumbra():
    # The umbra is a cone narrowing behind the Earth, the penumbra one widening:
    # umbra ⊂ cylinder ⊂ umbra ∪ penumbra, and the penumbra lasts seconds
    # (the Sun's 0.27° radius at 7.6 km/s in LEO: about 8 s each side).
    orbit, epoch = _equatorial_orbit_at_equinox()
    time_s = np.arange(0.0, orbit.period_s, 0.5)
    conical = orbit_references(orbit, epoch, time_s, "dipole", "conical").illumination
    cylinder = orbit_references(orbit, epoch, time_s, "dipole", "cylindrical").illumination
    umbra, penumbra = conical == 0.0, (conical > 0) & (conical < 1)
    assert np.all(cylinder[umbra] == 0.0)
    assert np.all(umbra | penumbra | (cylinder == 1.0))
    assert 4.0 < penumbra.sum() * 0.5 / 2 < 15.0
    assert np.all((conical >= 0) & (conical <= 1))


def test_illumination_is_one_on_the_sunlit_side():
    sun = np.array([[1.5e8, 0.0, 0.0]])
    assert illumination(np.array([[7000.0, 0.0, 0.0]]), sun, "conical")[0] == 1.0
    assert illumination(np.array([[-7000.0, 0.0, 0.0]]), sun, "conical")[0] == 0.0
    assert illumination(np.array([[-7000.0, 0.0, 0.0]]), sun, "cylindrical")[0] == 0.0


def test_circular_orbit_keeps_its_radius_and_period():
    orbit = CircularOrbit(500.0, 97.4, 10.0, 0.0, datetime(2026, 1, 1, tzinfo=UTC))
    r = orbit.positions_km(np.arange(0.0, orbit.period_s + 1, 60.0))
    assert np.allclose(np.linalg.norm(r, axis=1), EARTH_RADIUS_KM + 500.0, rtol=1e-12)
    assert orbit.period_s == pytest.approx(5676.98, abs=0.05)
    # Sun-synchronous at 97.4°: the node turns 360° a year (0.9856 °/day).
    assert math.degrees(orbit.node_rate_radps) * 86400 == pytest.approx(0.9856, abs=0.01)


ISS_TLE = ("1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991",
           "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482")


def test_a_two_line_element_set_propagates_with_sgp4():
    orbit = TLEOrbit(ISS_TLE)
    r = orbit.positions_km(np.arange(0.0, 5600.0, 60.0))
    radius = np.linalg.norm(r, axis=1)
    assert np.all((radius > 6770) & (radius < 6810))         # the ISS, about 410 km up
    inclination = math.degrees(math.acos(np.cross(r[0], r[1])[2] /
                                         np.linalg.norm(np.cross(r[0], r[1]))))
    assert inclination == pytest.approx(51.64, abs=0.05)


@pytest.mark.parametrize("lines, rule", [
    (("1 garbage", "x"), "two-line element set"),
    (("only one line",), "two-line element set"),
])
def test_a_bad_element_set_is_refused_by_name(lines, rule):
    with pytest.raises(InvalidParameterError, match=rule) as raised:
        TLEOrbit(lines)
    assert raised.value.name == "orbit.tle"
