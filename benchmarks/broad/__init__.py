"""The BROAD benchmark: real IMU trials (gyro, accelerometer, magnetometer)
against an optical reference, scored as the dataset's authors score them.

* :mod:`benchmarks.broad.dataset` — the published folder layout
  (``trials.json`` with ``data_mat/*.mat``, ``data_hdf5/*.hdf5`` or the
  toolkit's ``.npz``) read into :class:`sensors.recording.Recording` objects;
* :mod:`benchmarks.broad.metric` — the authors' error metric: total,
  heading and inclination RMSE over the movement phase;
* :mod:`benchmarks.broad.inputs` — a trial as the estimators' sensor data:
  the accelerometer as a gravity direction, the magnetometer as a field
  direction, their references and noise from the initial rest;
* :mod:`benchmarks.broad.benchmark` — every estimator on every trial, the
  per-trial and per-group tables; :mod:`benchmarks.broad.figures` — their
  figures;
* :mod:`benchmarks.broad.case_study` — the authors' published case study
  (Madgwick's and Mahony's filters), reproduced.

Laidig, Caruso, Cereatti & Seel, "BROAD — A Benchmark for Robust Inertial
Orientation Estimation", *Data* 6(7), 72, 2021 (CC BY 4.0).
"""
