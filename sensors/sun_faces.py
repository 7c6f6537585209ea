"""The coarse sun sensors' per-reading arithmetic, compiled: the choice of
the faces that give a first solution, and each reading's least-squares sum
over its lit faces (:class:`sensors.sun_sensor.CoarseSunSensors`).

Why compiled: a campaign measures every run's currents at every scheduled
step (a thousand CubeSat runs of one orbit: six million sets of six
currents), and the face choice is a short loop over the faces of each set in
order of brightness, which numpy can only run as whole-array passes, one per
face; those passes were two thirds of a CubeSat campaign's time. Each
comparison, product and sum here is the one the numpy passes made, in the
same order, so every reading keeps its bits (``tests/test_sun_faces.py``
holds them to the numpy passes, which it keeps as the reference). The loops
are serial and release the GIL: the engine draws the next block's readings
in a thread of its own while its kernels run the current block on every
core (:func:`benchmarks.engine.batch.run_batch`), and a parallel loop there
would start a second team of threads beside the kernels' (where numba's
threading layer is its own work queue, that is not allowed).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def first_faces(currents, normals, threshold, opposite, span_tolerance):
    """``(M, N)`` bool: per set of currents ``(M, N)``, the faces taken in
    order of brightness (a stable sort: ties keep their face order) — a face
    is taken unless three are and it reads at most ``threshold``, or a face
    ``opposite`` it is taken, or (with fewer than three) it adds no dimension
    to the taken faces' normals (their cross product, then triple product,
    at most ``span_tolerance``)."""
    sets, faces = currents.shape
    chosen = np.zeros((sets, faces), dtype=np.bool_)
    order = np.empty(faces, dtype=np.int64)     # one for all the sets: no allocation per set
    # Each face's opposite faces, listed once (a cube's face has one: the
    # test below then reads one face, not all six).
    opposites, n_opposite = np.empty((faces, faces), dtype=np.int64), np.zeros(faces, np.int64)
    for face in range(faces):
        for other in range(faces):
            if opposite[face, other]:
                opposites[face, n_opposite[face]] = other
                n_opposite[face] += 1
    for row in range(sets):
        c = currents[row]
        _brightest_first(c, order)
        count = 0
        f0 = f1 = f2 = s0 = s1 = s2 = 0.0      # the first two faces' normals
        for index in range(faces):
            face = order[index]
            if count >= 3 and c[face] <= threshold:
                continue
            if _opposite_taken(chosen[row], opposites[face], n_opposite[face]):
                continue
            n0, n1, n2 = normals[face, 0], normals[face, 1], normals[face, 2]
            if count == 1 or count == 2:
                # np.cross(first, n), and the norm and dot product numpy's reductions take.
                a0, a1, a2 = f1 * n2 - f2 * n1, f2 * n0 - f0 * n2, f0 * n1 - f1 * n0
                if count == 1 and not math.sqrt(a0 * a0 + (a1 * a1 + a2 * a2)) > span_tolerance:
                    continue
                if count == 2 and not abs(a0 * s0 + (a1 * s1 + a2 * s2)) > span_tolerance:
                    continue
            if count == 0:
                f0, f1, f2 = n0, n1, n2
            elif count == 1:
                s0, s1, s2 = n0, n1, n2
            chosen[row, face] = True
            count += 1
    return chosen


@njit(cache=True, inline="always")
def _opposite_taken(chosen, opposites, n_opposite):
    """Whether a face of ``opposites[:n_opposite]`` is ``chosen``."""
    for index in range(n_opposite):
        if chosen[opposites[index]]:
            return True
    return False


@njit(cache=True, inline="always")
def _brightest_first(c, order):
    """``order`` = the faces' indices by decreasing current, ties in face order
    (``np.argsort(-c, kind="stable")``; an insertion sort: a handful of faces)."""
    for i in range(len(c)):
        order[i] = i
    for i in range(1, len(c)):
        face = order[i]
        j = i - 1
        while j >= 0 and -c[order[j]] > -c[face]:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = face


@njit(cache=True, nogil=True)
def currents_in_sun(truth, sigma, noise, in_sun):
    """``(R·L, N)``: the currents ``truth + σ·noise`` of every run's steps
    ``in_sun`` (``truth`` ``(M, N)``, ``noise`` ``(R, M, N)``; ``L`` steps in
    the Sun), run by run, the rows that are solved for Sun vectors."""
    runs, faces = noise.shape[0], noise.shape[2]
    out = np.empty((runs * len(in_sun), faces))
    for r in range(runs):
        for index in range(len(in_sun)):
            m = in_sun[index]
            for face in range(faces):
                out[r * len(in_sun) + index, face] = truth[m, face] + sigma * noise[r, m, face]
    return out


@njit(cache=True, nogil=True)
def solve_sets(currents, lit, which, gains, solvable_sets, variances, solvable, solution,
               variance, normals):
    """Each set still ``solvable`` whose faces ``lit`` are set ``which`` of
    the distinct ones: its solution ``Σ c_f g_f`` over its lit faces in face
    order (``gains[which]``'s columns, one per lit face), from zero, and its
    set's variance; a set whose faces cannot be solved is no longer
    ``solvable``. In place. Returns the faces each solution lights, ``n_f ·
    b > 0`` (none for a set not solved), the next pass's ``lit``."""
    lights = np.zeros(lit.shape, dtype=np.bool_)
    for row in range(len(currents)):
        if not solvable[row]:
            continue
        index = which[row]
        if not solvable_sets[index]:
            solvable[row] = False
            continue
        s0, s1, s2 = 0.0, 0.0, 0.0
        column = 0
        for face in range(currents.shape[1]):
            if lit[row, face]:
                c = currents[row, face]
                s0 += c * gains[index, 0, column]
                s1 += c * gains[index, 1, column]
                s2 += c * gains[index, 2, column]
                column += 1
        solution[row, 0], solution[row, 1], solution[row, 2] = s0, s1, s2
        variance[row] = variances[index]
        for face in range(currents.shape[1]):   # as sensors.vector.times_matrix sums
            lights[row, face] = s0 * normals[face, 0] + s1 * normals[face, 1] + \
                s2 * normals[face, 2] > 0.0
    return lights


@njit(cache=True, nogil=True)
def scatter_solutions(solution, solved_variance, steps, body, variance, available):
    """The Sun vectors solved for each run's rows (:func:`currents_in_sun`'s
    order: run by run, a row per step of ``steps``), written in place where
    one was solved (a finite variance)."""
    for r in range(body.shape[0]):
        for index in range(len(steps)):
            row = r * len(steps) + index
            if math.isfinite(solved_variance[row]):
                k = steps[index]
                body[r, k, 0], body[r, k, 1], body[r, k, 2] = \
                    solution[row, 0], solution[row, 1], solution[row, 2]
                variance[r, k] = solved_variance[row]
                available[r, k] = True
