"""The coarse sun sensors' compiled face choice and least squares
(sensors/sun_faces.py) give the bits the numpy passes they replaced gave:
those passes are kept here, as they were, as the reference, down to each
run's readings as the former numpy ``measure_runs`` made them."""
import numpy as np
from hypothesis import given, settings, strategies as st

from sensors.sun_sensor import (CUBE_FACES, FULL_SUN, LIT_THRESHOLD_SIGMA, MAX_CONDITION,
                                OPPOSITE_COSINE, SPAN_TOLERANCE, CoarseSunSensors,
                                _distinct_rows)
from sensors.vector import normals, times_matrix, to_body
from tests.conftest import random_sky


def numpy_sun_vectors(self, currents: np.ndarray):
    """The least-squares Sun vectors of ``(M, N)`` sets of currents and
    their mean variances per axis, NaN where there is none: the faces of
    :meth:`_first_faces` give a first solution, then the faces it lights
    (``n_i · b > 0``) the final one (a face in the dark reads its noise,
    so the set is refined from the solution rather than from the
    currents alone). Solved once per distinct set of faces: there are
    few, and one reading's arithmetic is that of a single solve."""
    lit = numpy_first_faces(self, currents)
    solution = np.full((len(currents), 3), np.nan)
    variance = np.full(len(currents), np.nan)
    solvable = np.ones(len(currents), dtype=bool)
    for _ in range(2):
        sets, which = _distinct_rows(lit)
        for index, faces_lit in enumerate(sets):
            rows = np.flatnonzero(solvable & (which == index))
            if not len(rows):
                continue
            faces = self.normals[faces_lit]
            normal_matrix = faces.T @ faces
            if len(faces) < 3 or np.linalg.cond(normal_matrix) > MAX_CONDITION:
                solvable[rows] = False
                continue
            covariance = np.linalg.inv(normal_matrix)
            gain = covariance @ faces.T
            solution[rows] = 0.0
            for column, face in enumerate(np.flatnonzero(faces_lit)):
                solution[rows] += currents[rows, face:face + 1] * gain[:, column]
            variance[rows] = self.sigma ** 2 * np.trace(covariance) / 3.0
        lit = times_matrix(solution, self.normals) > 0.0
    solution[~solvable], variance[~solvable] = np.nan, np.nan
    return solution, variance

def numpy_first_faces(self, currents: np.ndarray) -> np.ndarray:
    """The former numpy pass of ``SunSensorArray._first_faces`` (its rule is
    in that docstring), taken face by face in order of brightness for
    every set at once: the reference the compiled pass must equal."""
    rows = np.arange(len(currents))
    chosen = np.zeros(currents.shape, dtype=bool)
    picked = np.zeros((len(currents), 2, 3))     # the first two faces' normals
    threshold = LIT_THRESHOLD_SIGMA * self.sigma
    opposite = self.normals @ self.normals.T < -OPPOSITE_COSINE
    for face in np.argsort(-currents, axis=1, kind="stable").T:
        count = chosen.sum(axis=1)
        normal = self.normals[face]
        take = ~((count >= 3) & (currents[rows, face] <= threshold)) & \
            ~np.any(chosen & opposite[face], axis=1)
        # Fewer than three so far: the face must add a dimension.
        across = np.cross(picked[:, 0], normal)
        spans = np.select([count == 0, count == 1, count == 2],
                          [np.ones(len(rows), dtype=bool),
                           np.linalg.norm(across, axis=1) > SPAN_TOLERANCE,
                           np.abs(np.sum(across * picked[:, 1], axis=1)) > SPAN_TOLERANCE],
                          default=True)
        take &= spans
        for few in (0, 1):
            first = take & (count == few)
            picked[first, few] = normal[first]
        chosen[rows[take], face[take]] = True
    return chosen


def same_readings(sensor, currents):
    solution, variance = sensor._sun_vectors(currents)
    expected_solution, expected_variance = numpy_sun_vectors(sensor, currents)
    assert np.array_equal(solution, expected_solution, equal_nan=True)
    assert np.array_equal(variance, expected_variance, equal_nan=True)
    assert np.array_equal(sensor._first_faces(currents), numpy_first_faces(sensor, currents))
    return solution


def cosine_currents(sensor, sun, rng):
    """Currents of the cosine law with the sensor's noise, Sun directions ``(M, 3)``."""
    lit = np.maximum(0.0, times_matrix(sun, sensor.normals))
    return lit + sensor.sigma * rng.standard_normal(lit.shape)


def test_the_cube_in_every_direction_reads_the_same_bits():
    rng = np.random.default_rng(11)
    sensor = CoarseSunSensors(0.01, 1.0, 0.1)
    sun = rng.standard_normal((20000, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    solution = same_readings(sensor, cosine_currents(sensor, sun, rng))
    # And they are Sun vectors: within a few σ_c of the truth (a sanity check
    # that the comparison is not between two wrong answers).
    found = np.isfinite(solution).all(axis=1)
    assert found.mean() > 0.99
    assert np.median(np.linalg.norm(solution[found] - sun[found], axis=1)) < 5 * sensor.sigma


def test_the_sun_on_a_face_or_in_its_plane_reads_the_same_bits():
    # The ties and the dark faces that stand in: the choice's hard cases.
    rng = np.random.default_rng(2)
    sensor = CoarseSunSensors(0.02, 1.0, 0.1)
    axes = np.repeat(np.array(CUBE_FACES), 500, axis=0)
    edges = np.repeat(np.array([[1.0, 1.0, 0.0], [0.0, -1.0, 1.0]]) / np.sqrt(2.0), 500, axis=0)
    sun = np.vstack([axes, edges])
    same_readings(sensor, cosine_currents(sensor, sun, rng))
    same_readings(sensor, np.zeros((10, 6)))                  # in the dark: no reading
    same_readings(sensor, np.ones((10, 6)))                   # every face equal


@settings(max_examples=40, deadline=None)
@given(faces=st.integers(3, 9), seed=st.integers(0, 2**32 - 1),
       sigma=st.floats(1e-4, 0.5), exact_zeros=st.booleans())
def test_any_faces_and_currents_read_the_same_bits(faces, seed, sigma, exact_zeros):
    rng = np.random.default_rng(seed)
    normals = rng.standard_normal((faces, 3))
    if faces >= 6 and seed % 2:
        normals[:6] = CUBE_FACES                      # opposite faces among them
    # Random normals span space (a set that does not is refused: tested above).
    sensor = CoarseSunSensors(sigma, 1.0, 0.1, normals=normals)
    currents = rng.standard_normal((300, faces)) * rng.choice([sigma, 1.0], (300, faces))
    if exact_zeros:
        currents[rng.random(currents.shape) < 0.3] = 0.0
    same_readings(sensor, currents)


def former_measure_runs(sensor, q_true, references, rngs, first_step):
    """The former numpy ``CoarseSunSensors.measure_runs``: the currents of
    every scheduled step, those in full Sun solved (by the reference passes
    above), scattered to each run's steps; body, variance and flags."""
    steps = np.flatnonzero(sensor.scheduled(len(q_true), first_step))
    s = to_body(q_true[steps], references.sun_unit[steps])
    lit_fraction = np.where(references.illumination[steps] >= FULL_SUN, 1.0, 0.0)
    currents = np.maximum(0.0, times_matrix(s, sensor.normals)) * lit_fraction[:, None] + \
        sensor.sigma * normals(rngs, (len(steps), len(sensor.normals)))
    in_sun = np.flatnonzero(lit_fraction > 0)
    solution, solved = numpy_sun_vectors(sensor,
                                         currents[:, in_sun].reshape(-1, len(sensor.normals)))
    body, variance = np.zeros((len(rngs), len(q_true), 3)), np.zeros((len(rngs), len(q_true)))
    available = np.zeros((len(rngs), len(q_true)), dtype=bool)
    body[:, steps[in_sun]] = solution.reshape(len(rngs), len(in_sun), 3)
    variance[:, steps[in_sun]] = solved.reshape(len(rngs), len(in_sun))
    available[:, steps[in_sun]] = np.isfinite(variance[:, steps[in_sun]])
    variance[~available] = 0.0
    return np.where(available[..., None], body, 0.0), variance, available


#: Five faces of the cube, the bottom one left out: with the Sun below, at
#: most four faces see it and no three of them can be solved.
FIVE_FACES = CUBE_FACES[:5]


def readings_and_former(seed, runs, first_step, interval, sigma, faces, steps=40):
    """A coarse sensor's readings of random attitudes and Sun directions
    (a fifth of the steps in the penumbra), and the former passes' of the same."""
    q, references = random_sky(seed, steps)
    sensor = CoarseSunSensors(sigma, interval * 0.1, 0.1, normals=faces)
    readings = sensor.measure_runs(q, references, [np.random.default_rng(seed + run)
                                                   for run in range(runs)], first_step)
    former = former_measure_runs(sensor, q, references,
                                 [np.random.default_rng(seed + run) for run in range(runs)],
                                 first_step)
    return readings, former, references


def assert_same_bits(readings, former):
    body, variance, available = former
    assert readings.body.tobytes() == body.tobytes()
    assert readings.variance.tobytes() == variance.tobytes()
    assert np.array_equal(readings.available, available)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 4), first_step=st.integers(0, 9),
       interval=st.integers(1, 3), sigma=st.sampled_from([1e-3, 0.02, 0.3]),
       faces=st.sampled_from([CUBE_FACES, FIVE_FACES]))
def test_the_readings_of_every_run_are_the_former_passes_bits(seed, runs, first_step, interval,
                                                              sigma, faces):
    """The whole reading, from the attitude to each run's written Sun vector,
    in any block of a run, through the penumbra (no reading) and the faces
    that cannot be solved: the former numpy passes' bits."""
    readings, former, references = readings_and_former(seed, runs, first_step, interval,
                                                       sigma, faces)
    assert_same_bits(readings, former)
    assert former[2].any() or not (references.illumination >= FULL_SUN).any()


def test_a_sun_no_three_faces_can_solve_gives_no_reading_as_before():
    """Five faces: in full Sun, the steps with the Sun below the body give
    no reading (the sets the least squares cannot solve), the others one,
    each the former passes' bits."""
    readings, former, references = readings_and_former(5, 3, 0, 1, 0.01, FIVE_FACES, 400)
    assert_same_bits(readings, former)
    in_sun = np.broadcast_to(references.illumination >= FULL_SUN, readings.available.shape)
    assert (in_sun & ~readings.available).sum() > 50        # the Sun below: unsolvable
    assert (in_sun & readings.available).sum() > 500
