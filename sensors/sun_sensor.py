r"""Sun sensors: a fine sun sensor (a unit vector with angular noise) and a
set of coarse sun sensors (cosine-law currents from the faces, as on CubeSats).

Both read only in sunlight: a step whose illumination
(:func:`dynamics.environment.illumination`) is below :data:`FULL_SUN` gives
no reading (the penumbra's dimmed Sun would bias either sensor). Earth
albedo is not modelled; innovation gating is how a filter rejects it.

**Fine sun sensor** (:class:`FineSunSensor`): with :math:`s = A(q)^\mathsf{T}
\hat r_\odot` the true body-frame Sun direction, it reads when the Sun is
within ``fov_deg`` of its boresight :math:`n`, :math:`s \cdot n \ge
\cos(\text{fov})`,

.. math:: b = \exp\bigl([\delta\times]\bigr)\, s, \qquad
          \delta \sim \mathcal N\bigl(0, \sigma^2 (I_3 - s s^\mathsf{T})\bigr),

a unit vector whose error, of σ per axis (rad), lies across it (2 degrees of
freedom). A datasheet's accuracy is this σ (e.g. the NewSpace Systems
NFSS-411: < 0.1° RMS over a 140° field of view).

**Coarse sun sensors** (:class:`CoarseSunSensors`): ``N`` photodiodes on
faces of outward normals :math:`n_i` (the six faces of a cube by default)
give currents, as fractions of the full-sun, normal-incidence current,

.. math:: c_i = \max(0,\ n_i \cdot s) + v_i, \qquad v_i \sim \mathcal N(0, \sigma_c^2)

(the cosine law; a face in the dark reads its noise). The faces reading
above :data:`LIT_THRESHOLD_SIGMA` σ_c, with at least the three brightest
faces whose normals span space (no two opposite), give a first solution, the
faces it lights the final one: the least-squares solution
:math:`b = (N_L^\mathsf{T} N_L)^{-1} N_L^\mathsf{T} c_L`, a full 3-vector with
covariance :math:`\sigma_c^2 (N_L^\mathsf{T} N_L)^{-1}` (:math:`\sigma_c^2
I_3` for the cube's three orthogonal lit faces), reported as its mean
variance per axis; faces whose normals do not span space give no reading.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics.validation import InvalidParameterError, finite_number, float_array, \
    standard_deviation, unit_vector
from sensors.vector import VectorSensor, normals, times_matrix, to_body

#: Illumination below which a sun sensor gives no reading (1: full Sun).
FULL_SUN = 0.99
#: A coarse sensor's face counts as lit when it reads above this many σ_c.
LIT_THRESHOLD_SIGMA = 3.0
#: Two faces whose normals' cosine is below minus this are opposite.
OPPOSITE_COSINE = 0.99
#: Normals span a plane when their cross product, and space when their
#: triple product, is larger than this (they are unit vectors).
SPAN_TOLERANCE = 1e-9
#: The lit faces' normal matrix must be better conditioned than this.
MAX_CONDITION = 1e6
#: The largest fine sun sensor σ, degrees: no direction is more than 180°
#: from another, so an angle's σ beyond it means nothing (long before it,
#: a reading is noise alone).
MAX_SIGMA_DEG = 180.0
#: The largest coarse sun sensor σ_c, a fraction of the full-sun current:
#: beyond the whole signal, every face reads its noise alone.
MAX_CURRENT_SIGMA = 1.0
#: The six faces of a cube, outward normals in the body frame.
CUBE_FACES = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0),
              (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))


def _distinct_rows(flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of a boolean ``(M, N)`` array and each row's index
    among them (``np.unique(axis=0)``, which sorts the rows as bytes, is ten
    times slower than sorting each row's bits read as a number)."""
    if flags.shape[1] > 62:
        return np.unique(flags, axis=0, return_inverse=True)
    codes = flags.astype(np.int64) @ (np.int64(1) << np.arange(flags.shape[1], dtype=np.int64))
    if flags.shape[1] <= 16:        # a table of every code: no sort (the same answer)
        present = np.zeros(1 << flags.shape[1], dtype=bool)
        present[codes] = True
        distinct = np.flatnonzero(present)
        which = (np.cumsum(present) - 1)[codes]
    else:
        distinct, which = np.unique(codes, return_inverse=True)
    return (distinct[:, None] >> np.arange(flags.shape[1]) & 1).astype(bool), which


class FineSunSensor(VectorSensor):
    """A fine sun sensor (module docstring).

    Parameters
    ----------
    sigma_deg : float
        Angular noise σ per axis across the Sun vector, degrees (> 0).
    interval_s, dt : float
    fov_deg : float
        Half-angle of the field of view about the boresight, degrees (0–90].
    boresight : (3,)
        The boresight in the body frame (normalised).
    """

    name = "sun_sensor"
    dof = 2

    def __init__(self, sigma_deg: float, interval_s: float, dt: float, *, fov_deg: float = 70.0,
                 boresight=(0.0, 0.0, 1.0)):
        super().__init__(interval_s, dt)
        sigma = standard_deviation("sun_sensor.sigma_deg", sigma_deg, strictly_positive=True)
        if sigma > MAX_SIGMA_DEG:
            raise InvalidParameterError("sun_sensor.sigma_deg", sigma_deg, f"must be at most "
                                        f"{MAX_SIGMA_DEG:g} degrees: no direction is further "
                                        "than that from another")
        self.sigma_rad = math.radians(sigma)
        fov = finite_number("sun_sensor.fov_deg", fov_deg, strictly_positive=True)
        if fov > 90.0:
            raise InvalidParameterError("sun_sensor.fov_deg", fov_deg,
                                        "must be at most 90 degrees (a half-angle)")
        self.fov_deg = fov
        self.boresight = unit_vector("sun_sensor.boresight", boresight)

    def measure_into(self, q_true: np.ndarray, references, rngs, first_step: int,
                     body: np.ndarray, variance: np.ndarray,
                     available: np.ndarray) -> np.ndarray:
        """Readings of the Sun direction ``references.sun_unit`` (``(N, 3)``,
        reference frame; :class:`dynamics.environment.References`); one
        3-vector of noise drawn per scheduled step, in time order, whether or
        not the Sun is seen (so the noise does not depend on the field of
        view). Each Sun vector is turned by its noise element by element
        (compiled: :func:`sensors.vector_arithmetic.turned_rows`, Rodrigues'
        formula): scipy's ``Rotation.apply`` gives a row a last-bit result
        that depends on its place in the stack, and a reading must not depend
        on how a run is cut into blocks."""
        from sensors.vector_arithmetic import turned_rows   # compiled: loaded where used
        sun_unit, illumination = references.sun_unit, references.illumination
        steps = np.flatnonzero(self.scheduled(len(q_true), first_step))
        s = to_body(q_true[steps], sun_unit[steps])
        seen = (times_matrix(s, self.boresight[None])[:, 0] >=
                math.cos(math.radians(self.fov_deg))) & (illumination[steps] >= FULL_SUN)
        turned_rows(s, self.sigma_rad, normals(rngs, (len(steps), 3)), steps, seen,
                    self.sigma_rad ** 2, body, variance, available)
        return sun_unit


class CoarseSunSensors(VectorSensor):
    """A set of coarse sun sensors on the body's faces (module docstring).

    Parameters
    ----------
    sigma : float
        Current noise σ_c, a fraction of the full-sun current (> 0).
    interval_s, dt : float
    normals : (N, 3)
        The faces' outward normals, body frame (normalised); the cube's six by default.
    """

    name = "coarse_sun_sensors"
    dof = 3

    def __init__(self, sigma: float, interval_s: float, dt: float, *, normals=CUBE_FACES):
        super().__init__(interval_s, dt)
        self.sigma = standard_deviation("coarse_sun_sensors.sigma", sigma,
                                        strictly_positive=True)
        if self.sigma > MAX_CURRENT_SIGMA:
            raise InvalidParameterError("coarse_sun_sensors.sigma", sigma, f"must be at most "
                                        f"{MAX_CURRENT_SIGMA:g} (the full-sun current): beyond "
                                        "it every face reads its noise alone")
        faces = float_array("coarse_sun_sensors.normals", normals,
                            "must be a list of 3-vectors (the faces' outward normals)")
        rule = ("must be at least three finite 3-vectors of non-zero length (the faces' "
                "outward normals)")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 3 or \
                not np.all(np.isfinite(faces)) or np.any(np.abs(faces).max(axis=1) == 0):
            raise InvalidParameterError("coarse_sun_sensors.normals", faces.tolist(), rule)
        # Normalised before the rank is taken: [1e300, 0, 0] is a direction too.
        units = np.array([unit_vector("coarse_sun_sensors.normals", face) for face in faces])
        if np.linalg.matrix_rank(units) < 3:
            raise InvalidParameterError("coarse_sun_sensors.normals", faces.tolist(),
                                        "must span three dimensions")
        self.normals = units

    def _sun_vectors(self, currents: np.ndarray):
        """The least-squares Sun vectors of ``(M, N)`` sets of currents and
        their mean variances per axis, NaN where there is none: the faces of
        :meth:`_first_faces` give a first solution, then the faces it lights
        (``n_i · b > 0``) the final one (a face in the dark reads its noise,
        so the set is refined from the solution rather than from the
        currents alone). Each distinct set of faces is solved once here
        (there are few); each reading's sum over its faces is compiled
        (:func:`sensors.sun_faces.solve_sets`)."""
        from sensors import sun_faces        # compiled: loaded where readings are made
        currents = np.ascontiguousarray(currents, dtype=float)
        lit = self._first_faces(currents)
        solution = np.full((len(currents), 3), np.nan)
        variance = np.full(len(currents), np.nan)
        solvable = np.ones(len(currents), dtype=bool)
        for _ in range(2):
            sets, which = _distinct_rows(lit)
            gains, variances, solvable_sets = self._set_solutions(sets)
            lit = sun_faces.solve_sets(currents, lit, np.asarray(which, dtype=np.int64), gains,
                                       solvable_sets, variances, solvable, solution, variance,
                                       self.normals)
        solution[~solvable], variance[~solvable] = np.nan, np.nan
        return solution, variance

    def _set_solutions(self, sets: np.ndarray) -> tuple:
        """Per distinct set of lit faces ``(S, N)``: its least-squares gain
        ``(N_Lᵀ N_L)⁻¹ N_Lᵀ`` (``(S, 3, N)``, a column per lit face in face
        order), its mean variance per axis σ_c² tr((N_Lᵀ N_L)⁻¹)/3, and
        whether it can be solved (three faces at least, well conditioned)."""
        gains = np.zeros((len(sets), 3, len(self.normals)))
        variances = np.full(len(sets), np.nan)
        solvable = np.zeros(len(sets), dtype=bool)
        for index, faces_lit in enumerate(sets):
            faces = self.normals[faces_lit]
            normal_matrix = faces.T @ faces
            if len(faces) < 3 or np.linalg.cond(normal_matrix) > MAX_CONDITION:
                continue
            covariance = np.linalg.inv(normal_matrix)
            gains[index, :, :len(faces)] = covariance @ faces.T
            variances[index] = self.sigma ** 2 * np.trace(covariance) / 3.0
            solvable[index] = True
        return gains, variances, solvable

    def _first_faces(self, currents: np.ndarray) -> np.ndarray:
        """``(M, N)`` bool: per set of currents, the faces reading above
        :data:`LIT_THRESHOLD_SIGMA` σ_c, and at least the three brightest
        whose normals span space, brightest first, leaving out a face
        opposite one already taken (the two cannot both be lit). With the
        Sun on a face's normal or in its plane, a face in the dark stands
        in: it reads its noise about zero, the cosine law's reading of a
        normal at 90° (its choice, the brighter of two noisy zeros, biases
        that axis by about 0.56 σ_c). Compiled, set by set
        (:func:`sensors.sun_faces.first_faces`)."""
        from sensors import sun_faces
        opposite = self.normals @ self.normals.T < -OPPOSITE_COSINE
        return sun_faces.first_faces(currents, self.normals, LIT_THRESHOLD_SIGMA * self.sigma,
                                     opposite, SPAN_TOLERANCE)

    def measure_into(self, q_true: np.ndarray, references, rngs, first_step: int,
                     body: np.ndarray, variance: np.ndarray,
                     available: np.ndarray) -> np.ndarray:
        """Least-squares Sun vectors from the faces' currents at every
        scheduled step in full Sun; one current noise per face drawn per
        scheduled step, in time order."""
        from sensors import sun_faces        # compiled: loaded where readings are made
        sun_unit, illumination = references.sun_unit, references.illumination
        steps = np.flatnonzero(self.scheduled(len(q_true), first_step))
        s = to_body(q_true[steps], sun_unit[steps])
        lit_fraction = np.where(illumination[steps] >= FULL_SUN, 1.0, 0.0)
        truth = np.maximum(0.0, times_matrix(s, self.normals)) * lit_fraction[:, None]
        in_sun = np.flatnonzero(lit_fraction > 0)
        currents = sun_faces.currents_in_sun(truth, self.sigma, normals(
            rngs, (len(steps), len(self.normals))), in_sun)
        solution, solved_variance = self._sun_vectors(currents)
        sun_faces.scatter_solutions(solution, solved_variance, steps[in_sun], body, variance,
                                    available)
        return sun_unit
