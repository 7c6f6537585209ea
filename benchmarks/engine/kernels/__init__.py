r"""Compiled kernels of the batched engine: one module per estimator, each
advancing every run of a batch through a block of steps.

Why compiled: the estimators' arithmetic is tiny (4-vectors, 4x4 and 6x6
covariances), so on the per-run path nearly all the time goes to Python and
numpy's call overhead, not to arithmetic. numba compiles each kernel's loop
to machine code; one run is one iteration of a loop over a share of the
batch's runs, one share per core (:mod:`~benchmarks.engine.kernels.cores`),
its steps a plain loop with small scratch arrays.

What a kernel module declares (``dead_reckoning.py`` is the shortest):

* ``NAME``, the registry name of the per-run estimator it twins;
* ``State``, its state as named arrays, and ``initial_state(estimators)``,
  which reads every setting off the per-run objects (one per run, built by
  ``from_scenario``), so the two paths can never disagree;
* ``advance_runs(first, last, block, sensors, state, record, row)``,
  compiled, serial and releasing the GIL, and ``advance(block, sensors,
  state, record, row)``, which runs it on every core
  (:func:`~benchmarks.engine.kernels.cores.on_every_core_of`): every run
  through a :class:`~benchmarks.engine.kernels.common.Block` (the truth and
  the noise of its sensors, whose readings
  :mod:`~benchmarks.engine.kernels.sensors` makes, advancing the
  :class:`~benchmarks.engine.kernels.sensors.SensorState` ``sensors``), its
  errors written into row ``row`` of the
  :class:`~benchmarks.engine.kernels.common.Record`
  (:func:`~benchmarks.engine.kernels.common.record_error`);
* optionally ``REPORTS_COVARIANCE = True`` with ``nis_dof(estimators)`` (it
  streams NEES and NIS), and ``final(state, estimators)`` (what it reports
  at the last step besides the statistics);
* optionally ``VECTOR_READINGS = True`` (it applies the block's vector
  readings, ``Block.vector_*``, made on the host by
  :mod:`benchmarks.engine.vectors`) and ``GATING = True`` (it gates readings
  as its per-run class does). Without them, a scenario with vector sensors
  or an estimator with a ``gate_probability`` runs on the per-run path
  (:func:`benchmarks.engine.batch.engine_limitation`), as does an estimator
  whose settings its kernel's ``limitation`` names.

:data:`KERNELS` maps a name to its module, in the engine's order. Adding an
estimator to the engine is its kernel module plus one line here. Each
formula is the same, in the same order, as its per-run reference, which
stays the readable definition; the tests hold the two paths to 1e-9 at
every step. Runs never interact (no reductions across the batch, no
fast-math reassociation), so a run's numbers are bit-identical whatever
batch it is computed in.

Inside ``advance_runs`` the loop touches plain arrays only: every read of
a named tuple's field there costs a reference count (inside the parallel
loop the kernels had before, the loop took three times as long, and numba
dropped writes into a named tuple's arrays made there).
So each kernel unpacks its block, its record and its state before the loop
(``gyro_arrays`` …). An array read every step is passed on by itself: a
plain tuple's item read in the loop costs a reference count too (the EKF's
batch 5 % slower with the gyro's arrays as a tuple); the star tracker's,
read at its readings, go as their tuple (no change measured). A called
function counts a reference of every array it takes, alone or in a tuple:
USQUE's ``_correct``, called every step, takes the vector sensors' arrays
as their tuple at the cost it had taking them one by one, but the MEKF's
``_vector_reading``, called with the whole block and state, took a third
longer on a recording (readings at every sample); inlined, it reads the
arrays it needs off them where a reading comes. The IMU models' readings,
called, take the dozen arrays each reads as a plain tuple made before the
loop (``imu.gravity_models``): with the whole state, passed on to three
called helpers, they cost the MEKF 0.67 µs a sample of 3.73 on a BROAD trial.

Those counts are atomic operations on the array's counter, each a barrier
to the processor's reordering, and where the two threads count the same
array (the batch's state, block and record) its cache line goes back and
forth between the cores: in a profile of 128 CubeSat MEKF runs a fifth of
all the process's samples fell on them. So the MEKF's and USQUE's kernels
take every array their loop reads borrowed
(:mod:`~benchmarks.engine.kernels.borrowed`: the same array without its
counter, whose views and calls count nothing), the block and the state
borrowed again inside each run's iteration (a named tuple made before the
loop cannot enter it), and each run's working arrays as borrowed rows of
arrays made once for the batch. In the same profile the counts then took
under 3 % of the samples; the numbers are the same to the bit. Since the
runs' loops are serial (one share of the runs per thread, where numba's
parallel loop once passed its arrays to each thread without a count per
use), every kernel borrows so: with its arrays counted, the EKF's kernel
took 4.5 times as long, dead reckoning's 6 times, with resets 3 times.

Its run index is made ``run = np.int64(index)`` first, one integer type
for every compiled helper taking ``run`` (numba typed a parallel loop's
index as unsigned inside it and signed outside, and compiled each such
helper twice: the MEKF's and USQUE's reading helpers, with their IMU
models, about 15 s).

What a kernel inlines (``inline="always"``) and what it calls: a helper run
at every step (the gyro's reading, the propagation, the output's
bookkeeping) is inlined, since a compiled call counts a reference of each
array it takes, every step (the MEKF's loop ran 20 % slower with its
propagation called). An update, which a reading makes, and a divergence's
bookkeeping are called: inlined, they were compiled again at each caller
(the MEKF's Joseph update, 12 s of its compile; the EKF's update, 8 s).
USQUE's propagation is called although it runs every step: its 13 sigma
points outweigh the call, and inlined at its two places (before the
readings with the trapezoidal rate, after them otherwise) it took 9 s more
to compile.
The MEKF's Joseph update has no copy of its own for six states (loops of
a constant length): it ran no faster so, and took 10 s of the compile.

The EKF's and the MEKF's kernels have a second form for a campaign's case
(statistics only): :mod:`~benchmarks.engine.kernels.ekf_lanes` and
:mod:`~benchmarks.engine.kernels.mekf_lanes` advance eight runs side by
side in the processor's vector instructions
(:mod:`~benchmarks.engine.kernels.lanes`), the same numbers to the bit;
``ekf.advance`` and ``mekf.advance`` choose them where they apply.
"""
from __future__ import annotations

import importlib

#: Registry name → kernel module (its import path; numba loads on first use).
KERNELS = {
    "dead-reckoning": "benchmarks.engine.kernels.dead_reckoning",
    "dead-reckoning-resets": "benchmarks.engine.kernels.resets",
    "ekf": "benchmarks.engine.kernels.ekf",
    "mekf": "benchmarks.engine.kernels.mekf",
    "usque": "benchmarks.engine.kernels.usque",
}


def kernel(name: str):
    """The kernel module of estimator ``name`` (a module registered as an
    object, as a test's toy kernel is, is returned as it is)."""
    from benchmarks.engine.cache import keep_fresh
    keep_fresh()            # the cached kernels match their sources (engine.cache)
    module = KERNELS[name]
    return importlib.import_module(module) if isinstance(module, str) else module


def settings_limitation(module, name: str, settings: dict) -> str | None:
    """What of estimator ``name``'s ``settings`` (its constructor's keywords,
    or a per-run object's attributes) kernel ``module`` does not model (its
    ``limitation(settings)``, if it declares one; the per-run path runs
    those), or None."""
    check = getattr(module, "limitation", None)
    found = None if check is None else check(settings)
    return None if found is None else f"{found} for {name}"
